"""``kesbrdf plot``: the real CLI on a small model; user errors exit 2 and write nothing."""

import json

import pytest

pytest.importorskip("matplotlib")  # an optional extra (kesbrdf[plot])

from kesbrdf.cli.main import main
from kesbrdf.plotting.save import read_png_text

EXIT_USER_ERROR = 2


@pytest.fixture(scope="module")
def files(satin_model, satin_measurement, tmp_path_factory):
    from kesbrdf.io.measurement_csv import write_measurement

    d = tmp_path_factory.mktemp("cli")
    satin_model.save(d / "m.kes.json")
    write_measurement(d / "m.csv", satin_measurement)
    (d / "bad.kes.json").write_text("{not json")
    return d


def test_plot_one_png_with_provenance(files, tmp_path, capsys):
    out = tmp_path / "f4.png"
    rc = main(["plot", str(files / "m.kes.json"), "--measurement", str(files / "m.csv"),
               "--figure", "4", "--gamma-deg=-30,0,30", "--dpi", "40", "-o", str(out)])
    assert rc == 0
    text = read_png_text(out.read_bytes())
    record = json.loads(text["kesbrdf_provenance"])
    assert record["parameters"]["gamma_deg"] == [-30.0, 0.0, 30.0]
    assert len(record["model_file_sha256"]) == 64
    assert text["input_sha256"] == record["input_sha256"]
    assert "wrote" in capsys.readouterr().err


def test_plot_all_into_a_folder_as_svg(files, tmp_path):
    rc = main(["plot", str(files / "m.kes.json"), "--reference", "satin-ward", "--figure", "all",
               "--format", "svg", "-o", str(tmp_path / "figs")])
    assert rc == 0
    names = sorted(p.name for p in (tmp_path / "figs").iterdir())
    assert names == ["fig3a.svg", "fig3b.svg", "fig4.svg", "fig5.svg", "fig6.svg", "figalbedo.svg"]
    assert all((tmp_path / "figs" / n).read_text().lstrip().startswith("<?xml") for n in names)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["MISSING", "--figure", "5"], "No such file"),
        (["BAD", "--figure", "5"], "expected a kesbrdf model file"),
        (["GOOD", "--figure", "all"], "expected a folder for --figure all"),
        (["GOOD", "--figure", "5", "--channel", "Q"], "expected a channel in ['value'], got 'Q'"),
        (["GOOD", "--figure", "4", "--gamma-deg", "a,b"], "--gamma-deg: expected numbers"),
        (["GOOD", "--figure", "6", "--reference", "ward", "--reference-params", "[1"], "--reference-params"),
    ],
)
def test_plot_user_errors_exit_2_without_output(files, tmp_path, capsys, argv, message):
    model = {"MISSING": str(files / "missing.kes.json"), "BAD": str(files / "bad.kes.json"),
             "GOOD": str(files / "m.kes.json")}[argv[0]]
    out = tmp_path / "out.png"
    rc = main(["plot", model, *argv[1:], "-o", str(out)])
    assert rc == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_plot_rejects_unknown_suffix(files, tmp_path, capsys):
    rc = main(["plot", str(files / "m.kes.json"), "--figure", "5", "-o", str(tmp_path / "f.jpg")])
    assert rc == EXIT_USER_ERROR and "ending in .png, .svg or .pdf" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
