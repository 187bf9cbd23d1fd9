"""``kesbrdf drape`` through the real CLI entry point."""

import json

import pytest

from kesbrdf.cli.main import main


@pytest.mark.parametrize("argv, match", [
    (["--fps", "-3"], "fps"),
    (["--resolution", "2"], "resolution"),
    (["--frames", "0"], "frames"),
    (["--density-gsm", "5000"], "density"),
    (["--turn-deg", "30"], "--scene garment"),
    (["--scene", "garment", "--turn-deg", "30", "--turn-duration", "0"], "turn_duration_s"),
])
def test_bad_values_exit_2_with_one_line(tmp_path, capsys, argv, match):
    assert main(["drape", "-o", str(tmp_path / "d"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("kesbrdf: error:") and match in err and "\n" not in err


@pytest.mark.parametrize("argv", [["--scene", "cube"], ["--frames", "many"]])
def test_unparsable_arguments_exit_2(tmp_path, capsys, argv):
    with pytest.raises(SystemExit) as exc:
        main(["drape", "-o", str(tmp_path / "d"), *argv])
    assert exc.value.code == 2
    assert "drape" in capsys.readouterr().err


@pytest.mark.cloth
def test_cli_writes_and_resumes(tmp_path, capsys):
    pytest.importorskip("newton")
    out = tmp_path / "d"
    assert main(["drape", "--scene", "sphere", "-o", str(out), "--frames", "3", "--resolution", "6"]) == 0
    assert main(["drape", "--scene", "sphere", "-o", str(out), "--frames", "5", "--resolution", "6"]) == 0
    meta = json.loads((out / "drape.json").read_text())
    assert len(meta["frames"]) == 5 and meta["complete"]
    assert main(["drape", "--scene", "sphere", "-o", str(out), "--frames", "5", "--resolution", "7"]) == 2
    assert "--overwrite" in capsys.readouterr().err
