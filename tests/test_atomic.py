"""kesbrdf._atomic: the target is never corrupted, and no temporary outlives a write."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from kesbrdf._atomic import STALE_LEGACY_SECONDS, atomic_path, remove_stale, write_text

#: How long the killed writer may take to start and report that it is writing (s).
STARTUP_TIMEOUT_S = 60.0


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_failure_inside_the_block_keeps_the_old_target_and_removes_the_temporary(tmp_path):
    target = tmp_path / "model.kes.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half-writ")
            raise RuntimeError("disk full")
    assert target.read_text() == "old"
    assert _hidden(tmp_path) == []


def test_keyboard_interrupt_removes_the_temporary(tmp_path):
    target = tmp_path / "m.csv"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("x")
            raise KeyboardInterrupt
    assert not target.exists() and _hidden(tmp_path) == []


def test_keep_suffix_ends_the_temporary_with_the_targets_suffix(tmp_path):
    with atomic_path(tmp_path / "a.mp4", keep_suffix=True) as tmp:
        assert tmp.name.endswith(".part.mp4") and tmp.name.startswith(".a.mp4.")
        tmp.write_bytes(b"v")
    assert (tmp_path / "a.mp4").read_bytes() == b"v"


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid  # finished and reaped: no such process (unless the pid is reused at once)


def test_stale_temporaries_of_dead_writers_are_removed_on_the_next_write(tmp_path):
    target = tmp_path / "m.csv"
    dead = tmp_path / f".m.csv.{_dead_pid()}-abc123_x.part"
    alive = tmp_path / f".m.csv.{os.getppid()}-zzzzzzzz.part"  # our parent runs: a concurrent writer
    other = tmp_path / f".n.csv.{_dead_pid()}-abc123_x.part"  # another target's temporary
    legacy_old = tmp_path / ".m.csv.k2j3h4g5.part"
    legacy_new = tmp_path / ".m.csv.q1w2e3r4.part"
    for p in (dead, alive, other, legacy_old, legacy_new):
        p.write_text("partial")
    old = time.time() - 2 * STALE_LEGACY_SECONDS
    os.utime(legacy_old, (old, old))
    write_text(target, "new")
    assert target.read_text() == "new"
    assert _hidden(tmp_path) == sorted([alive.name, other.name, legacy_new.name])


def test_remove_stale_ignores_a_missing_folder(tmp_path):
    assert remove_stale(tmp_path / "nope" / "x.csv") == []


WRITER = r"""
import sys, time
from kesbrdf._atomic import atomic_path
with atomic_path(sys.argv[1]) as tmp:
    with open(tmp, "w") as fh:
        fh.write("partial new content")
        fh.flush()
        print("writing", flush=True)
        time.sleep(120)
"""


def test_sigkill_mid_write_keeps_the_target_and_the_next_run_cleans_up(tmp_path):
    target = tmp_path / "model.kes.json"
    target.write_text("old complete model")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[1] / "src"), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(target)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        line = ""
        while time.monotonic() < deadline and "writing" not in line:
            line = proc.stdout.readline()
            if not line and proc.poll() is not None:
                break
        assert "writing" in line, "the writer did not start"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_text() == "old complete model"  # never corrupted
    leftovers = _hidden(tmp_path)
    assert len(leftovers) == 1 and leftovers[0].endswith(".part")  # what SIGKILL leaves
    write_text(target, "new model")
    assert target.read_text() == "new model"
    assert _hidden(tmp_path) == []


def test_a_directory_as_target_is_named_not_the_temporary(tmp_path):
    """`-o somedir`: the error names somedir (the CLI prints `somedir: expected a file ...`),
    and nothing is left behind in it or beside it."""
    from kesbrdf._atomic import write_text

    target = tmp_path / "adir"
    target.mkdir()
    with pytest.raises(IsADirectoryError) as exc:
        write_text(target, "x")
    assert exc.value.filename == str(target) and "directory" in exc.value.strerror
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir"] and not any(target.iterdir())


def test_the_file_is_fsynced_before_the_rename_and_its_folder_after(tmp_path, monkeypatch):
    """A power cut after the rename must not leave an empty target: the data reaches the
    disk (fsync of the temporary) before the rename, the rename after (fsync of the folder)."""
    import os

    from kesbrdf._atomic import write_bytes

    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.path.realpath(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd")
                       else fd))
        real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.fspath(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    target = tmp_path / "model.kes.json"
    write_bytes(target, b"{}")
    kinds = [e[0] for e in events]
    assert kinds == ["fsync", "replace", "fsync"], events
    if os.path.exists("/proc/self/fd"):  # Linux: check what was synced
        assert events[0][1].startswith(str(tmp_path / ".model.kes.json.")) and events[0][1].endswith(".part")
        assert events[2][1] == str(tmp_path)


# -- write errors (issue 16): one OutputError naming the target and the cause --------------
@pytest.mark.parametrize("code,words", [
    (28, "disk full"), (30, "read-only file system"), (13, "permission denied"), (5, "input/output error"),
])
def test_a_failing_write_is_one_output_error_and_leaves_nothing(tmp_path, monkeypatch, code, words):
    from faults import failing_writes, listing

    from kesbrdf.errors import OutputError

    target = tmp_path / "new" / "m.kes.json"
    failing_writes(monkeypatch, tmp_path, code, at="create" if code in (30, 13) else "write")
    with pytest.raises(OutputError) as info:
        write_text(target, "x" * 10_000)
    monkeypatch.undo()
    assert str(info.value).startswith(f"cannot write {target}: ") and words in str(info.value)
    assert info.value.errno == code and "\n" not in str(info.value)
    assert listing(tmp_path) == []  # no temporary, no half file, not even the folder made for it


def test_an_input_error_inside_the_block_is_not_called_a_write_error(tmp_path):
    """Only errors about the target or its temporary are translated: a missing input stays itself."""
    with pytest.raises(FileNotFoundError):
        with atomic_path(tmp_path / "out.png") as tmp:
            (tmp_path / "missing-frame.png").read_bytes()
    assert list(tmp_path.iterdir()) == []


def test_a_name_near_the_limit_gets_a_shortened_temporary(tmp_path):
    """240 bytes is a legal name; the temporary's would be ~265 without shortening."""
    target = tmp_path / ("n" * 235 + ".json")
    with atomic_path(target) as tmp:
        assert len(tmp.name.encode()) <= 255
        tmp.write_text("{}")
    assert target.read_text() == "{}" and _hidden(tmp_path) == []


def test_a_name_past_the_limit_fails_before_writing(tmp_path):
    from kesbrdf.errors import OutputError

    with pytest.raises(OutputError, match="file name too long \\(305 bytes"):
        with atomic_path(tmp_path / ("a" * 300 + ".json")):
            raise AssertionError("the block must not run")
    assert list(tmp_path.iterdir()) == []
