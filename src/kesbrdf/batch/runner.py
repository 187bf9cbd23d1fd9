"""Run one fabric's steps with the skip rule (what every Dask task calls).

:func:`run_fabric` walks the fabric's steps in pipeline order.  For each step it
computes the key (input hashes + parameters + versions, :mod:`kesbrdf.batch.manifest`);
when ``OUT/<fabric>/<step>/manifest.json`` has that key **and every output it lists
still has its recorded sha256** the step is *skipped* and its stored result reused;
otherwise (a missing, emptied or altered output) it computes the step in a scratch
folder, writes the manifest last, and commits the folder in one rename.

Every step function (and the hashing of the catalogue input) runs in a step process
(:mod:`~kesbrdf.batch.isolation`) that is killed when it runs longer than
``task_timeout`` seconds; the step then fails with a one-line reason.  Inputs that
are not regular files (a FIFO, a device, a folder) are refused before they are opened
(:func:`kesbrdf.io.files.open_regular`).

Errors:

* :class:`~kesbrdf.errors.KesbrdfError` (a timeout included) and missing/unreadable
  input files are the fabric's fault: the step is recorded ``failed`` with the one-line message, the steps
  that need it are ``blocked``, the others still run, and nothing is retried.
* Anything else (a crashed library, a crashed step process, a full disk, a killed
  worker) propagates, so the scheduler retries the task; finished steps are skipped on
  the retry.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from kesbrdf.batch import isolation
from kesbrdf._atomic import write_text
from kesbrdf.batch import manifest as mf
from kesbrdf.batch.catalog import DEFAULT_OPTIONS, Fabric
from kesbrdf.batch.steps import DEPENDS, STEP_FUNCTIONS, closure, input_files, step_params
from kesbrdf.batch.store import Store, is_url
from kesbrdf.errors import KesbrdfError
from kesbrdf.io.files import sha256_file

__all__ = ["run_fabric", "run_chunk", "fabric_options", "PERMANENT_ERRORS", "TEST_HOOKS_ENV", "DEFAULT_TASK_TIMEOUT"]

#: Exceptions that are the input's fault: reported, never retried.
PERMANENT_ERRORS = (KesbrdfError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError,
                    ImportError)
#: Test-only hook file (JSON); see :func:`_test_hooks`.
TEST_HOOKS_ENV = "KESBRDF_BATCH_TEST_HOOKS"
#: Longest a step of one fabric may run, in seconds (``--task-timeout``).  The slowest
#: step measured is an export with every RGL format, ~30 s wall on a loaded 2-core
#: machine (docs/batch.md "Performance"); 10 minutes is 20 times that, and bounds the
#: time a hung step holds a worker.
DEFAULT_TASK_TIMEOUT = 600.0


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    return " ".join(str(exc).split()) or type(exc).__name__


def _test_hooks(step: str, fabric: str) -> None:
    """Test-only fault injection, active only when ``$KESBRDF_BATCH_TEST_HOOKS`` names a JSON file.

    ``{"sleep": {"steps": [...], "seconds": s}}`` slows steps down (to kill things
    mid-run, or to make them time out; the sleep runs in the step process), only of
    ``"fabrics": [...]`` when given, and records ``<fabric>.<step>.<pid>`` in
    ``"record": DIR`` when given (the process to check that a timeout killed);
    ``{"fail_once": {"steps": [...], "fabrics": [...], "record": DIR}}`` raises a transient ``RuntimeError`` on the first attempt of each (fabric, step)
    and records every attempt as a file in DIR.
    """
    path = os.environ.get(TEST_HOOKS_ENV)
    if not path or not os.path.isfile(path):
        return
    hooks = json.loads(Path(path).read_text())
    sleep = hooks.get("sleep")
    if sleep and step in sleep.get("steps", ()) and fabric in sleep.get("fabrics", (fabric,)):
        if sleep.get("record"):
            record = Path(sleep["record"])
            record.mkdir(parents=True, exist_ok=True)
            (record / f"{fabric}.{step}.{os.getpid()}").write_text("sleeping\n")
        time.sleep(float(sleep["seconds"]))
    fail = hooks.get("fail_once")
    if fail and step in fail.get("steps", ()) and fabric in fail.get("fabrics", ()):
        record = Path(fail["record"])
        record.mkdir(parents=True, exist_ok=True)
        n = len(list(record.glob(f"{fabric}.{step}.*")))
        write_text(record / f"{fabric}.{step}.{n}.{os.getpid()}", "attempt\n")
        if n == 0:
            raise RuntimeError(f"injected transient failure in {fabric}/{step} (test hook)")


def _source_name(fabric: Fabric) -> str:
    """How downstream steps name the measurement: the catalogue input (a manifest's
    measurement is marked as ingested from it)."""
    src = fabric.input
    return f"{src} (ingested)" if src.endswith("manifest.csv") else src


class _Input:
    """The catalogue input, made local (downloaded when it is a URL)."""

    def __init__(self, fabric: Fabric):
        self.fabric = fabric
        self._path: Path | None = None
        self._tmp: Path | None = None

    def cleanup(self) -> None:
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)

    def path(self) -> Path:
        if self._path is None:
            src = self.fabric.input
            if is_url(src) and not src.startswith("file://"):
                import fsspec

                fs, p = fsspec.core.url_to_fs(src)
                tmp = self._tmp = Path(tempfile.mkdtemp(prefix="kesbrdf-batch-input-"))
                if not fs.exists(p):
                    raise FileNotFoundError(2, "No such file or directory", src)
                with fs.open(p, "rb") as fh:
                    head = fh.read(64)
                if head.lstrip(b"\xef\xbb\xbf").lstrip().startswith(b"# kesbrdf-manifest"):
                    fs.get(p.rsplit("/", 1)[0] + "/", str(tmp) + "/", recursive=True)
                    self._path = tmp / p.rsplit("/", 1)[1]
                else:
                    fs.get_file(p, str(tmp / p.rsplit("/", 1)[-1]))
                    self._path = tmp / p.rsplit("/", 1)[-1]
            else:
                self._path = Path(src[len("file://"):] if src.startswith("file://") else src)
        return self._path


def run_fabric(fabric: Fabric, out: Store | str, steps, settings: dict | None = None,
               task_timeout: float | None = DEFAULT_TASK_TIMEOUT) -> dict:
    """Run (or skip) ``steps`` and what they need for one fabric; returns its record.

    The record: ``{"id", "status": ok|failed, "error", "failed_step", "steps":
    {step: {"status": done|skipped|failed|blocked, "seconds", "result", "outputs"}}}``.
    A step found in the store whose outputs no longer match their manifest has
    ``"stale"``: why it was recomputed.  ``task_timeout`` (seconds; None or 0: none, and
    the steps run in this process) bounds each step (:mod:`~kesbrdf.batch.isolation`).
    """
    store = out if isinstance(out, Store) else Store(out)
    settings = settings or {}
    t_start = time.perf_counter()
    record = {"id": fabric.id, "input": fabric.input, "status": "ok", "error": None, "failed_step": None,
              "steps": {}, "pid": os.getpid()}
    if fabric.error:
        record.update(status="failed", error=fabric.error, failed_step="catalog")
        return record
    options = fabric_options(fabric)
    vers = mf.versions()
    src = _Input(fabric)
    cache = None if store.local else tempfile.mkdtemp(prefix="kesbrdf-batch-cache-")
    try:
        _run_steps(fabric, store, steps, settings, options, vers, src, cache, record, task_timeout)
    finally:
        if cache:
            shutil.rmtree(cache, ignore_errors=True)
        src.cleanup()
    record["seconds"] = time.perf_counter() - t_start
    return record


def fabric_options(fabric: Fabric) -> dict:
    """A fabric's options: its catalogue row over :data:`~kesbrdf.batch.catalog.DEFAULT_OPTIONS`
    (what :func:`~kesbrdf.batch.steps.step_params` builds every step's parameters from)."""
    return {**DEFAULT_OPTIONS, **fabric.options}


def _ingest_inputs(path: Path) -> tuple[list[Path], dict]:
    """The files the ingest step reads (the input, a manifest's frames) and their sha256."""
    files = input_files(path)
    base = files[0].parent
    return files, {"input/" + p.relative_to(base).as_posix() if p.is_relative_to(base) else str(p):
                   sha256_file(p) for p in files}


def _call_step(step: str, fabric_id: str, inputs: dict, params: dict, scratch: Path) -> dict:
    """One step function (what the step process runs)."""
    _test_hooks(step, fabric_id)
    return STEP_FUNCTIONS[step](inputs, params, scratch)


def _stale(store: Store, fabric_id: str, step: str, outputs: dict) -> str | None:
    """Why a committed step's files do not match its manifest (None when they all do)."""
    for name, digest in outputs.items():
        try:
            got = store.sha256(fabric_id, step, name)
        except (OSError, KesbrdfError) as exc:  # e.g. replaced by a FIFO or a folder
            return f"{name}: {_one_line(exc)}"
        if got is None:
            return f"{name}: missing"
        if got != digest:
            return f"{name}: content differs from its manifest (sha256 {got[:12]}…, expected {digest[:12]}…)"
    return None


def _run_steps(fabric, store, steps, settings, options, vers, src, cache, record, task_timeout) -> None:
    manifests: dict[str, dict] = {}
    env = {TEST_HOOKS_ENV: os.environ.get(TEST_HOOKS_ENV)}
    for step in closure(steps):
        t0 = time.perf_counter()
        entry = {"status": None, "seconds": 0.0, "result": {}, "outputs": {}}
        record["steps"][step] = entry
        if any(record["steps"].get(d, {}).get("status") in ("failed", "blocked") for d in DEPENDS[step]):
            entry["status"] = "blocked"
            continue
        what = f"{fabric.id}: step {step}"
        try:
            params = step_params(step, options, settings)
            if step == "ingest":
                files, inputs = isolation.run(_ingest_inputs, (src.path(),), task_timeout, env,
                                              what=f"{what} (reading the input)")
                local_inputs = {"input": files[0]}
            else:
                inputs, local_inputs = {}, {"source": _source_name(fabric)}
                for d in DEPENDS[step]:
                    dirpath = store.local_dir(fabric.id, d, cache=cache)
                    for name, digest in manifests[d]["outputs"].items():
                        inputs[f"{d}/{name}"] = digest
                        local_inputs[f"{d}/{name}"] = dirpath / name
            key = mf.step_key(step, inputs, params, vers)
            old = mf.parse_manifest(store.read_bytes(fabric.id, step, mf.MANIFEST))
            if old is not None and old.get("key") == key:
                why = _stale(store, fabric.id, step, old.get("outputs") or {})
                if why is None:
                    manifests[step] = old
                    entry.update(status="skipped", result=old.get("result", {}), outputs=old.get("outputs", {}),
                                 computed_seconds=old.get("seconds"))
                    entry["seconds"] = time.perf_counter() - t0
                    continue
                entry["stale"] = why
            scratch = store.scratch(fabric.id, step)
            try:
                t1 = time.perf_counter()
                result = isolation.run(_call_step, (step, fabric.id, local_inputs, params, scratch), task_timeout,
                                       env, what=what)
                seconds = time.perf_counter() - t1
                outputs = {p.relative_to(scratch).as_posix(): sha256_file(p)
                           for p in sorted(scratch.rglob("*")) if p.is_file()}
                doc = mf.make_manifest(fabric.id, step, inputs, params, vers, outputs, result, seconds,
                                       pid=os.getpid(), finished_unix=time.time())
                write_text(scratch / mf.MANIFEST, json.dumps(doc, indent=1, sort_keys=True, default=str) + "\n")
                if not store.commit(scratch, fabric.id, step, mf.MANIFEST):
                    doc = mf.parse_manifest(store.read_bytes(fabric.id, step, mf.MANIFEST)) or doc
            except BaseException:
                store.discard(scratch)
                raise
            manifests[step] = doc
            entry.update(status="done", result=doc["result"], outputs=doc["outputs"], computed_seconds=seconds)
        except PERMANENT_ERRORS as exc:
            entry["status"] = "failed"
            if record["error"] is None:
                record.update(status="failed", error=_one_line(exc), failed_step=step)
        except Exception as exc:  # transient: the caller retries; say where it happened
            try:
                exc.kesbrdf_step = step
            except (AttributeError, TypeError):  # pragma: no cover - exceptions without a __dict__
                pass
            raise
        entry["seconds"] = time.perf_counter() - t0


_STORES: dict = {}


def _store(url: str, storage_options: dict | None) -> Store:
    """One Store per (URL, options) per process (building an fsspec file system costs ms)."""
    key = (url, json.dumps(storage_options or {}, sort_keys=True, default=str))
    if key not in _STORES:
        _STORES[key] = Store(url, storage_options)
    return _STORES[key]


def run_chunk(fabrics, url: str, storage_options: dict | None, steps, settings: dict | None = None,
              task_timeout: float | None = DEFAULT_TASK_TIMEOUT) -> list[dict]:
    """:func:`run_fabric` for several fabrics (one Dask task amortises its overhead).

    A transient exception of one fabric does not stop the others: its record gets
    ``status="transient"`` and the error, and the driver resubmits that fabric while it
    has retries left.  Finished steps are skipped on the retry, so nothing is redone.
    """
    store = _store(url, storage_options)
    out = []
    for fab in fabrics:
        try:
            out.append(run_fabric(fab, store, steps, settings, task_timeout))
        except Exception as exc:  # anything but a fabric error: retried by the driver
            out.append({"id": fab.id, "input": fab.input, "status": "transient",
                        "failed_step": getattr(exc, "kesbrdf_step", None),
                        "error": " ".join(f"{type(exc).__name__}: {exc}".split()), "steps": {}})
    return out
