"""``kesbrdf showcase``: bad input is one line and exit 2, before anything is simulated."""

import pytest

from kesbrdf.cli.main import main


@pytest.mark.parametrize("argv,words", [
    (["--resolution", "12"], "expected WIDTHxHEIGHT"),
    (["--resolution", "8x8"], "expected 16..7680 x 16..4320"),
    (["--spp", "0"], "expected samples a pixel in [1, 4096]"),
    (["--frames", "500"], "expected 1..108"),
    (["missing.kes.json"], "missing.kes.json"),
])
def test_bad_showcase_input_is_one_line(tmp_path, capsys, argv, words):
    assert main(["showcase", *argv, "-o", str(tmp_path / "sc")]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err, err
    assert not (tmp_path / "sc").exists()  # nothing written
