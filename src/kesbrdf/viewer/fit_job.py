"""A fit of an uploaded CSV in its own process, killed at its work budget.

The server never parses or fits an upload itself: :class:`FitRunner` hands the CSV to
a ``python -m kesbrdf.viewer.fit_job`` process on stdin and reads one JSON answer from
stdout.  Each process serves one upload; the next one is started ahead (its Python
and the fit's modules loaded while it waits), so an upload does not wait for a start.
The child limits its own CPU time (``RLIMIT_CPU`` = ``fit_cpu_s``; the kernel stops it
with SIGXCPU) and the parent kills it at ``fit_wall_s`` of wall-clock time, so one
upload costs at most its budget whatever its content.  At most
``fit_workers`` fits run at once and ``fit_queue`` wait; further uploads get 503.

Answers (``status``, JSON document):

* 200 ``{"model", "measurement", "size"}``: fitted;
* 400 ``{"error"}``: the CSV is malformed (the CLI's message) or not UTF-8;
* 413 ``{"error"}``: too many channels or rows x channels for the kind
  (:func:`kesbrdf.viewer.upload.check_upload_work`), or a too large answer;
* 422 ``{"error"}``: the fit did not finish within its CPU or wall-clock budget;
* 503 ``{"error"}``: every fit slot and queue place is taken.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import signal
import sys
from pathlib import Path

from kesbrdf.viewer.limits import ViewerLimits

__all__ = ["FitRunner", "budget_message", "main"]

#: Threads a fit may use inside its process (BLAS, OpenMP): the server shares the machine.
_CHILD_THREADS = "1"


def budget_message(name: str, limits: ViewerLimits) -> str:
    """The one-line refusal of a fit that ran out of its work budget."""
    return (
        f"{name}: the fit did not finish within the viewer's work budget ({limits.fit_cpu_s:g} CPU-s, "
        f"{limits.fit_wall_s:g} s wall-clock; kesbrdf view --fit-cpu-s, --fit-wall-s); "
        f"fit it with 'kesbrdf fit {name}' and open the model file"
    )


class FitRunner:
    """Runs fits in child processes: at most ``fit_workers`` at once, ``fit_queue`` waiting."""

    def __init__(self, limits: ViewerLimits) -> None:
        self.limits = limits
        self._slots = asyncio.Semaphore(limits.fit_workers)
        self._waiting = 0
        self._spare = None  # a started, warm fit process (a Task until it has started)

    async def fit(self, data: bytes, name: str, fallback: str | None) -> tuple[int, dict]:
        """``(status, document)`` for an upload (module docstring)."""
        limits = self.limits
        if self._slots.locked() and self._waiting >= limits.fit_queue:
            return 503, {
                "error": f"{name}: the viewer is busy: {limits.fit_workers} fit(s) running and "
                f"{self._waiting} waiting (kesbrdf view --fit-workers); try again when they are done"
            }
        self._waiting += 1
        try:
            await self._slots.acquire()
        finally:
            self._waiting -= 1
        try:
            return await self._run(data, name, fallback)
        finally:
            self._slots.release()
            self.prepare()  # the next upload's process warms up once this fit is over

    def prepare(self) -> None:
        """Start a warm fit process (Python and the fit's imports loaded) unless one is ready.

        Call from the event loop; the viewer does when its page is loaded and after
        each fit, so an upload does not wait for a Python start.
        """
        if self._spare is None:
            self._spare = asyncio.ensure_future(self._spawn(warm=True))

    async def close(self) -> None:
        """Stop the warm process, if any (server shutdown)."""
        spare, self._spare = self._spare, None
        if spare is None:
            return
        try:
            proc = await spare
        except OSError:
            return
        if proc.returncode is None:
            proc.kill()
            await proc.wait()

    async def _spawn(self, warm: bool = False):
        return await asyncio.create_subprocess_exec(
            sys.executable, "-m", "kesbrdf.viewer.fit_job", json.dumps(self.limits.to_json()),
            *(["--warm"] if warm else []),
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
            env=_child_env(),
        )

    async def _take(self):
        """The warm process if it is alive, else a new one."""
        spare, self._spare = self._spare, None
        proc = None
        if spare is not None:
            try:
                proc = await spare
            except OSError:
                proc = None
        if proc is None or proc.returncode is not None:
            proc = await self._spawn()
        return proc

    async def _run(self, data: bytes, name: str, fallback: str | None) -> tuple[int, dict]:
        limits = self.limits
        request = json.dumps({"name": name, "fallback": fallback}).encode() + b"\n"
        proc = await self._take()
        try:
            out, err = await asyncio.wait_for(proc.communicate(request + data), limits.fit_wall_s)
        except TimeoutError:
            return 422, {"error": budget_message(name, limits)}
        finally:
            if proc.returncode is None:  # over the wall-clock budget, or the request was cancelled
                proc.kill()
                await asyncio.shield(proc.wait())
        if proc.returncode in (-signal.SIGXCPU, -signal.SIGKILL):
            return 422, {"error": budget_message(name, limits)}
        if proc.returncode != 0:
            last = (err.decode("utf-8", "replace").strip().splitlines() or ["no message"])[-1]
            return 500, {"error": f"internal error: the fit process exited with code {proc.returncode}: {last}"}
        doc = await asyncio.get_running_loop().run_in_executor(None, json.loads, out)
        return int(doc.pop("status")), doc


def _child_env() -> dict:
    """The server's environment, kesbrdf importable, one thread per fit."""
    import kesbrdf

    root = str(Path(kesbrdf.__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = _CHILD_THREADS
    return env


def _limit_cpu(seconds: float) -> None:
    """SIGXCPU (terminates) after ``seconds`` of CPU time, SIGKILL one second later."""
    import resource

    soft = max(1, math.ceil(seconds))
    resource.setrlimit(resource.RLIMIT_CPU, (soft, soft + 1))


def _answer(limits: ViewerLimits, request: dict, data: bytes) -> dict:
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.viewer.upload import UploadTooLarge, check_upload_work, fit_csv_bytes

    name, fallback = request["name"], request["fallback"]
    try:
        check_upload_work(data, name, limits)
        model, measurement = fit_csv_bytes(data, name, fallback)
    except UploadTooLarge as exc:
        return {"status": 413, "error": str(exc)}
    except KesbrdfError as exc:
        return {"status": 400, "error": str(exc)}
    except UnicodeDecodeError as exc:
        return {"status": 400, "error": f"{name}: expected UTF-8 text, got undecodable bytes ({exc.reason})"}
    size = len(json.dumps(model)) + len(json.dumps(measurement))
    if size > limits.max_response_bytes:
        return {
            "status": 413,
            "error": f"{name}: the fitted model would be {size} bytes of JSON, limit {limits.max_response_bytes} bytes",
        }
    return {"status": 200, "model": model, "measurement": measurement, "size": size}


def _warm_up() -> None:
    """Load the modules a fit uses (about 1 CPU-s, mostly scipy)."""
    import kesbrdf.fitting  # noqa: F401
    import kesbrdf.io.measurement_csv  # noqa: F401
    import kesbrdf.models.kes  # noqa: F401
    import kesbrdf.viewer.upload  # noqa: F401

    try:
        import scipy.optimize  # noqa: F401 - the scattered and prior fits
    except ImportError:
        pass


def main(argv: list[str] | None = None) -> int:
    """Child entry point: ``python -m kesbrdf.viewer.fit_job LIMITS_JSON [--warm]``.

    Limits its CPU time, loads the fit's modules (``--warm``: a process started ahead of
    its upload; otherwise they load as the fit needs them), then reads one request from stdin:
    a JSON line ``{"name", "fallback"}`` followed by the CSV bytes; writes one JSON
    answer to stdout.  An empty stdin (a warm process never used) exits at once.
    """
    args = argv if argv is not None else sys.argv[1:]
    limits = ViewerLimits(**json.loads(args[0]))
    _limit_cpu(limits.fit_cpu_s)
    if "--warm" in args[1:]:  # loaded while waiting: the upload does not pay for it
        _warm_up()
    line = sys.stdin.buffer.readline()
    if not line:
        return 0
    data = sys.stdin.buffer.read()
    doc = _answer(limits, json.loads(line), data)
    sys.stdout.write(json.dumps(doc))
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    code = main()
    sys.stderr.flush()
    os._exit(code)  # skip the interpreter's teardown (scipy & co.: about 0.5 s): the answer is written
