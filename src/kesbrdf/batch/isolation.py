"""Running a step in a child process that is killed at its deadline (docs/batch.md "Timeouts").

A step runs numpy, Mitsuba and file reads in the caller's thread.  A step that hangs
there (a read that blocks, a deadlock inside a library, an endless loop) cannot be
interrupted: Python has no way to stop a thread.  So every step runs in a **step
process**, a child Python process (``python -c ...``, a fresh interpreter: no fork of a
process that may have run Dr.Jit) that the caller reuses for step after step:

* :func:`run` sends ``fn(*args)`` (``fn`` a module-level function, pickled by name)
  and waits for the answer at most ``timeout`` seconds;
* on time, the value comes back, or the exception the step raised (pickled; one that
  does not pickle comes back as :class:`KesbrdfError` / ``OSError`` / ``RuntimeError``
  with the same one-line message);
* past the deadline the step process (and anything it started) is killed with SIGKILL,
  :class:`StepTimeout` is raised, and the next call starts a fresh process;
* a step process that dies on its own (a segfault, the OOM killer) raises
  :class:`StepProcessDied`, a transient error that the batch retries.

Each calling thread holds its own step process (a Dask worker with one thread has
one), started on first use and kept until the caller exits.  A step process exits by
itself when its parent goes away (pipe closed, or parent pid changed: checked twice a
second), so a killed worker never leaves one behind.  The cost per step is one pickle
round trip over a pipe (well under a millisecond); starting a step process costs one
interpreter start plus the imports of the first step (about a second), once.

``timeout`` of ``None`` or 0 runs ``fn`` in the caller, without a child (no timeout;
handy under a debugger); so does any platform that is not POSIX (Windows).
"""

from __future__ import annotations

import atexit
import json
import os
import pickle
import signal
import subprocess
import sys
import threading
import traceback

from kesbrdf.errors import KesbrdfError

__all__ = ["run", "StepTimeout", "StepProcessDied", "StepProcess", "shutdown"]


class StepTimeout(KesbrdfError):
    """A step did not finish within its time limit; its process was killed."""


class StepProcessDied(RuntimeError):
    """The step process died while running a step (a crash, not the step's input)."""


#: Longest a step process may take to start (an interpreter and this module's imports;
#: ~0.3 s idle, a few seconds on a loaded machine).  Not counted against a step's limit.
STARTUP_LIMIT_S = 120.0

_BOOT = ("import json, sys; sys.path[:] = json.loads(sys.argv[1]); "
         "from kesbrdf.batch.isolation import _serve; _serve(int(sys.argv[2]), int(sys.argv[3]))")


class StepProcess:
    """One child interpreter that runs functions sent to it, one at a time."""

    def __init__(self):
        self.proc: subprocess.Popen | None = None
        self._send = self._recv = None

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def start(self) -> None:
        from multiprocessing.connection import Connection

        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-c", _BOOT, json.dumps(sys.path), str(to_child_r), str(from_child_w)],
                pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
                start_new_session=True,  # its own process group: a timeout kills what it started too
            )
        except BaseException:
            for fd in (to_child_w, from_child_r):
                os.close(fd)
            raise
        finally:
            os.close(to_child_r)
            os.close(from_child_w)
        self._send = Connection(to_child_w, readable=False)
        self._recv = Connection(from_child_r, writable=False)
        try:  # wait for it to be up, so its start-up does not count against the first step
            ready = self._recv.poll(STARTUP_LIMIT_S) and self._recv.recv() == "ready"
        except (EOFError, OSError):
            ready = False
        if not ready:
            code = self.kill()
            raise StepProcessDied(f"the step process did not start within {STARTUP_LIMIT_S:g} s "
                                  f"(exit status {code})")

    def call(self, fn, args: tuple, timeout: float, env: dict | None = None, what: str = "the step"):
        """``fn(*args)`` in the child; raises what it raised, or :class:`StepTimeout`
        (``"<what> did not finish within <timeout> s ..."``)."""
        if not self.alive:
            self.close()
            self.start()
        payload = pickle.dumps((fn, tuple(args)))  # fails here, in the caller, if it does not pickle
        try:
            self._send.send((list(sys.path), os.getcwd(), dict(env or {})))
            self._send.send_bytes(payload)
        except OSError as exc:
            self.kill()
            raise StepProcessDied(f"the step process stopped before the step started ({exc})") from None
        try:
            if not self._recv.poll(timeout):
                self.kill()
                raise StepTimeout(f"{what} did not finish within {timeout:g} s (--task-timeout); "
                                  "its process was killed")
            ok, value = self._recv.recv()
        except (EOFError, OSError):
            code = self.kill()
            how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            raise StepProcessDied(f"the step process died during the step ({how})") from None
        except BaseException:  # KeyboardInterrupt while waiting: the child must not run on
            self.kill()
            raise
        if ok:
            return value
        raise value

    def kill(self) -> int | None:
        """Kill the child and its process group; returns its exit status."""
        code = None
        if self.proc is not None:
            if self.proc.poll() is None:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError, AttributeError):  # pragma: no cover
                    self.proc.kill()
            code = self.proc.wait()
        self.close()
        return code

    def close(self) -> None:
        """Close the pipes (an idle child then exits by itself) and forget the child."""
        for conn in (self._send, self._recv):
            if conn is not None:
                conn.close()
        self._send = self._recv = None
        if self.proc is not None and self.proc.poll() is None:
            try:
                self.proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None


_LOCAL = threading.local()
_ALL: list[StepProcess] = []
_ALL_LOCK = threading.Lock()


def _mine() -> StepProcess:
    sp = getattr(_LOCAL, "proc", None)
    if sp is None:
        sp = _LOCAL.proc = StepProcess()
        with _ALL_LOCK:
            _ALL.append(sp)
    return sp


def run(fn, args: tuple = (), timeout: float | None = None, env: dict | None = None, what: str = "the step"):
    """``fn(*args)`` in this thread's step process, killed after ``timeout`` seconds.

    The step process takes this process's ``sys.path`` and working folder for the
    call; ``env`` variables are set in it before the call (the child is reused, so it
    does not see later changes of this process's environment otherwise).  With
    ``timeout`` None or 0, ``fn`` runs here, in the caller.
    """
    if not timeout or os.name != "posix":  # pass_fds, process groups and SIGKILL are POSIX
        return fn(*args)
    return _mine().call(fn, args, float(timeout), env, what)


@atexit.register
def shutdown() -> None:
    """Stop every step process of this process (idle ones exit when their pipe closes)."""
    with _ALL_LOCK:
        procs = list(_ALL)
    for sp in procs:
        sp.close()


# -- the child side -------------------------------------------------------------------
def _portable(exc: BaseException, tb: str) -> BaseException:
    """``exc`` if it survives pickling, else an exception of a base class with its message."""
    try:
        exc.child_traceback = tb
    except (AttributeError, TypeError):  # pragma: no cover - exceptions without a __dict__
        pass
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # noqa: BLE001 - any failure to round-trip
        pass
    msg = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, KesbrdfError):
        return KesbrdfError(msg)
    if isinstance(exc, OSError):
        return OSError(exc.errno, exc.strerror or msg, exc.filename)
    return RuntimeError(f"{type(exc).__name__}: {msg}")


def _orphan_watch(ppid: int) -> None:
    import time

    while True:
        time.sleep(0.5)
        if os.getppid() != ppid:
            os._exit(70)


def _serve(fd_in: int, fd_out: int) -> None:
    """The child's loop: receive (sys.path, cwd, env), then (fn, args); answer (ok, value)."""
    from multiprocessing.connection import Connection

    threading.Thread(target=_orphan_watch, args=(os.getppid(),), daemon=True).start()
    recv = Connection(fd_in, writable=False)
    send = Connection(fd_out, readable=False)
    send.send("ready")
    while True:
        try:
            path, cwd, env = recv.recv()
            payload = recv.recv_bytes()
        except (EOFError, OSError):
            return
        if sys.path != path:
            sys.path[:] = path
            import importlib

            importlib.invalidate_caches()
        if os.getcwd() != cwd:  # relative input paths mean what they mean in the caller
            os.chdir(cwd)
        for k, v in env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        try:
            fn, args = pickle.loads(payload)  # after sys.path is set: fn's module may need it
            answer = (True, fn(*args))
        except BaseException as exc:  # noqa: BLE001 - everything goes back to the caller
            answer = (False, _portable(exc, traceback.format_exc()))
        try:
            send.send(answer)
        except Exception as exc:  # noqa: BLE001 - a result that does not pickle
            send.send((False, RuntimeError(f"the step's result could not be sent back: {exc}")))
