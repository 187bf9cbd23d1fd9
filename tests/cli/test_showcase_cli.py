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


def test_progress_in_a_log_is_a_line_every_ten_frames_with_an_eta(monkeypatch, capsys):
    """Outside a terminal rich draws no bar: the clip's progress goes to the log as plain
    lines, each tenth frame and the last, with an ETA from the mean time a frame."""
    from kesbrdf.cli import showcase

    from types import SimpleNamespace

    clock = iter(float(t) for t in range(0, 1000, 2))  # 2 s a frame
    # the module's own clock only (patching time.perf_counter itself would let any other
    # caller in the process use up ticks)
    monkeypatch.setattr(showcase, "time", SimpleNamespace(perf_counter=lambda: next(clock)))
    log = showcase._ProgressLog()
    for done in range(0, 25):
        log("render", done, 24)
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["render: 10/24, 0:20 elapsed, ETA 0:28",
                     "render: 20/24, 0:40 elapsed, ETA 0:08",
                     "render: 24/24, 0:48 elapsed"]
