"""``kesbrdf report``: the real CLI writes one self-contained HTML file."""

import re

import pytest

pytest.importorskip("matplotlib")  # an optional extra (kesbrdf[plot])

from kesbrdf.cli.main import main

EXIT_USER_ERROR = 2


@pytest.fixture(scope="module")
def files(satin_model, satin_measurement, tmp_path_factory):
    from kesbrdf.io.measurement_csv import write_measurement

    d = tmp_path_factory.mktemp("cli-report")
    satin_model.save(d / "m.kes.json")
    write_measurement(d / "m.csv", satin_measurement)
    (d / "bad.kes.json").write_bytes(b"\x00\x01binary")
    return d


def test_report_with_measurement(files, tmp_path, capsys):
    out = tmp_path / "report.html"
    rc = main(["report", str(files / "m.kes.json"), "--measurement", str(files / "m.csv"), "-o", str(out)])
    assert rc == 0
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    text = out.read_text(encoding="utf-8")
    assert text.count("<img ") == 6  # 3a, 3b, 4, 5, 6 (model maps only: no reference), albedo
    assert "not drawn" not in text
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    for section in ("round_trip", "leave_one_orientation_out", "reciprocity_error", "residual_135"):
        assert section in text
    assert "wrote" in capsys.readouterr().err


def test_report_bad_model_exit_2_no_output(files, tmp_path, capsys):
    out = tmp_path / "r.html"
    rc = main(["report", str(files / "bad.kes.json"), "-o", str(out)])
    assert rc == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "bad.kes.json" in err and "Traceback" not in err
    assert not out.exists()


def test_report_needs_html_suffix(files, tmp_path, capsys):
    rc = main(["report", str(files / "m.kes.json"), "-o", str(tmp_path / "r.txt")])
    assert rc == EXIT_USER_ERROR and "expected a file ending in .html" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
