"""The step process: values and errors come back, a hang is killed, a crash is transient."""

from __future__ import annotations

import os
import time

import pytest

from kesbrdf.batch import isolation
from kesbrdf.errors import FormatError, KesbrdfError

pytestmark = pytest.mark.skipif(os.name != "posix", reason="the step process is POSIX-only")

#: Far above a pickle round trip (0.25 ms measured) and an interpreter start (~0.3-1 s),
#: far below the sleeps the tests kill.
LIMIT_S = 10.0


class _Unpicklable(Exception):
    def __init__(self, a, b):  # pickling re-calls __init__ with one argument: fails
        super().__init__(f"{a} and {b}")


def _raise_unpicklable():
    raise _Unpicklable("x", "y")


def _raise_format():
    raise FormatError("a.csv:3: expected a number, got 'n/a'")


def _sleep_and_report(seconds, path):
    with open(path, "w") as fh:
        fh.write(str(os.getpid()))
    time.sleep(seconds)


def test_values_and_errors_come_back_from_the_step_process():
    child = isolation.run(os.getpid, (), LIMIT_S)
    assert child != os.getpid()
    assert isolation.run(os.getpid, (), LIMIT_S) == child  # reused, not restarted
    with pytest.raises(FormatError, match=r"^a.csv:3: expected a number, got 'n/a'$"):
        isolation.run(_raise_format, (), LIMIT_S)
    with pytest.raises(FileNotFoundError) as exc:
        isolation.run(open, ("/no/such/file",), LIMIT_S)
    assert exc.value.filename == "/no/such/file"
    with pytest.raises(RuntimeError, match=r"^_Unpicklable: x and y$"):
        isolation.run(_raise_unpicklable, (), LIMIT_S)
    assert isolation.run(os.getpid, (), LIMIT_S) == child  # errors do not cost the process
    assert isolation.run(os.getpid, (), 0) == os.getpid()  # no timeout: in the caller


def test_a_hang_is_killed_at_the_deadline_and_a_crash_is_transient(tmp_path):
    pid_file = tmp_path / "pid"
    t0 = time.perf_counter()
    with pytest.raises(isolation.StepTimeout) as exc:
        isolation.run(_sleep_and_report, (60, str(pid_file)), 1.0, what="fab: step fit")
    assert time.perf_counter() - t0 < LIMIT_S
    assert isinstance(exc.value, KesbrdfError)  # the fabric's failure, not retried
    assert str(exc.value) == "fab: step fit did not finish within 1 s (--task-timeout); its process was killed"
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid_file.read_text()), 0)  # really stopped, and reaped
    with pytest.raises(isolation.StepProcessDied, match=r"died during the step \(exit code 3\)"):
        isolation.run(os._exit, (3,), LIMIT_S)
    assert not isinstance(isolation.StepProcessDied("x"), KesbrdfError)  # retried by the batch
    assert isolation.run(sum, ([1, 2],), LIMIT_S) == 3  # a fresh step process


def test_the_step_process_follows_the_callers_folder_and_path(tmp_path, monkeypatch):
    isolation.run(os.getcwd, (), LIMIT_S)  # started elsewhere
    monkeypatch.chdir(tmp_path)
    assert isolation.run(os.getcwd, (), LIMIT_S) == str(tmp_path)  # a relative input means the same file
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "kesbrdf_isolation_probe.py").write_text("def f():\n    return 'found'\n")
    import kesbrdf_isolation_probe

    assert isolation.run(kesbrdf_isolation_probe.f, (), LIMIT_S) == "found"
