"""Scheduling a batch: Dask distributed (local cluster or an existing one), or serial.

* ``workers=0``: every fabric runs in this process, one after the other (the serial
  baseline; also handy under a debugger).
* no ``scheduler``: a :class:`distributed.LocalCluster` of ``workers`` worker
  *processes* (one thread each) bound to 127.0.0.1, no dashboard unless asked for
  (then on 127.0.0.1 only).  Worker processes are **spawned**, never forked: a process
  that has run Dr.Jit cannot be forked safely (files silently missing, hangs; see
  docs/batch.md).  Workers get a node-local Dr.Jit kernel cache (``DRJIT_CACHE_DIR``
  under the node's temp folder), a Dr.Jit thread count of cores // workers, and
  single-threaded BLAS, so k workers never oversubscribe the cores.  When Mitsuba and
  libLLVM are present every worker advertises the resource ``render=1``.
* ``scheduler="tcp://host:port"`` (or a ``distributed.Client``): an existing cluster
  (dask-jobqueue, the Kubernetes operator, ``dask scheduler`` + ``dask worker``).  A
  worker plugin sets the same environment on every worker; render workers must be
  started with ``--resources render=1``.

One core task runs the non-render steps of a few fabrics (:func:`auto_chunk`: about
eight tasks per worker, at most 16 fabrics, which amortises Dask's per-task cost;
:func:`kesbrdf.batch.runner.run_chunk`); the preview step is one task per fabric that
asks for ``resources={"render": 1}``.  Retries are counted per fabric by this driver:
a fabric whose step raised anything but a fabric error, or whose task's workers kept
dying (``KilledWorker``, after Dask's own rescheduling), is resubmitted alone up to
``retries`` times.  Every retry is cheap and safe because finished steps are skipped
by their manifests.  Each step runs in a step process killed after ``task_timeout``
seconds (:mod:`kesbrdf.batch.isolation`): a hung step fails its fabric, never the run.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import importlib.util
import logging
import os
import tempfile
import time
import uuid
from dataclasses import dataclass, field

from kesbrdf.batch.catalog import Fabric, check_id, read_catalog
from kesbrdf.batch.runner import DEFAULT_TASK_TIMEOUT, run_chunk
from kesbrdf.batch.steps import RENDER_STEPS, closure
from kesbrdf.batch.store import Store

__all__ = ["run_batch", "BatchResult", "DEFAULT_STEPS", "start_local_cluster", "render_available", "worker_env",
           "run_tasks"]

DEFAULT_STEPS = ("ingest", "fit", "validate", "report", "export", "preview")
#: Largest number of fabrics in one core task (:func:`auto_chunk`).
MAX_CHUNK = 16


@dataclass
class BatchResult:
    """What :func:`run_batch` did."""

    out: str
    records: list
    counts: dict
    seconds: float
    summary: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    dashboard: str | None = None
    workers: int = 0


#: Less background work per process: no statistical profiler (it samples every task's
#: stack 100 times a second), memory and system monitors at 1 s and 2 s instead of 0.1 s
#: and 0.5 s.  Tasks here last 50 ms to minutes, so nothing is lost.
QUIET_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.worker.memory.monitor-interval": "1s",
                "distributed.admin.system-monitor.interval": "2s"}


def render_available() -> bool:
    """Mitsuba installed and a libLLVM found (checked without importing Dr.Jit)."""
    from kesbrdf._drjit import LLVM_CANDIDATES

    if importlib.util.find_spec("mitsuba") is None or importlib.util.find_spec("drjit") is None:
        return False
    llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    return bool(llvm and os.path.exists(llvm)) or any(os.path.exists(p) for p in LLVM_CANDIDATES)


def worker_env(n_workers: int, cores: int | None = None) -> dict:
    """Environment for worker processes on one node (no oversubscription, local caches)."""
    from kesbrdf._drjit import LLVM_CANDIDATES

    cores = cores or os.cpu_count() or 1
    env = {
        "DRJIT_CACHE_DIR": os.path.join(tempfile.gettempdir(), f"kesbrdf-drjit-{os.getuid()}"),
        "KESBRDF_DRJIT_THREADS": str(max(1, cores // max(1, n_workers))),
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "MPLBACKEND": "Agg",
    }
    llvm = os.environ.get("DRJIT_LIBLLVM_PATH") or next((p for p in LLVM_CANDIDATES if os.path.exists(p)), None)
    if llvm:
        env["DRJIT_LIBLLVM_PATH"] = llvm
    return env


def _worker_plugin(env: dict):
    from distributed.diagnostics.plugin import WorkerPlugin

    class KesbrdfWorkerSetup(WorkerPlugin):
        """Set the batch environment on a worker before any task imports Dr.Jit."""

        name = "kesbrdf-batch-setup"

        def __init__(self, env):
            self.env = dict(env)

        def setup(self, worker):
            for k, v in self.env.items():
                if k == "DRJIT_CACHE_DIR":  # node-local: this worker's temp folder
                    v = os.path.join(tempfile.gettempdir(), f"kesbrdf-drjit-{os.getuid()}")
                if k == "KESBRDF_DRJIT_THREADS":
                    continue  # set per node by whoever started the workers, else Dr.Jit's default
                os.environ.setdefault(k, v)

    return KesbrdfWorkerSetup(env)


def start_local_cluster(n_workers: int, dashboard: bool | str = False, env: dict | None = None,
                        render: bool | None = None):
    """A loopback-only LocalCluster of spawned single-threaded worker processes."""
    import dask
    from distributed import LocalCluster

    if render is None:
        render = render_available()
    dash = None
    if dashboard:
        dash = dashboard if isinstance(dashboard, str) else "127.0.0.1:0"
        if not dash.startswith("127.0.0.1") and not dash.startswith("localhost"):
            dash = f"127.0.0.1:{dash.rsplit(':', 1)[-1]}"
    if dask.config.get("distributed.worker.multiprocessing-method") != "spawn":
        # globally, not in a context: nannies also use it when they restart a killed worker
        dask.config.set({"distributed.worker.multiprocessing-method": "spawn"})
    with dask.config.set(QUIET_CONFIG):  # the nannies (in this process) read it when built
        return LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
            dashboard_address=dash, resources={"render": 1} if render else None,
            env={**worker_env(n_workers), **(env or {})}, silence_logs=logging.ERROR,
            # passed to the spawned workers whole (the nanny replaces, not merges, it)
            config=copy.deepcopy(dask.config.config),
            # without a dashboard the scheduler still serves /health and /metrics over
            # HTTP: keep that on a random loopback port (not 8787, not a public interface)
            scheduler_kwargs=None if dash else {"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        )


def chunks(fabrics: list, size: int, n_workers: int) -> list[list]:
    """Groups of ``size`` fabrics, then single fabrics for the last ``size × workers``
    (guided scheduling: big tasks amortise Dask's cost, the small ones at the end keep
    every worker busy until the last fabric, so no worker idles behind a long task)."""
    tail = min(len(fabrics), size * max(1, n_workers)) if size > 1 else 0
    head = len(fabrics) - tail
    out = [fabrics[k:min(k + size, head)] for k in range(0, head, size)]
    return out + [[f] for f in fabrics[head:]]


def _transient_record(fabric: Fabric, error: str, step: str, attempts: int) -> dict:
    return {"id": fabric.id, "input": fabric.input, "status": "failed", "failed_step": step,
            "error": f"transient failure persisted after {attempts} attempt(s): {error}", "steps": {}}


def auto_chunk(n_fabrics: int, n_workers: int) -> int:
    """Fabrics per task: about 8 tasks per worker (so the last tasks leave little idle
    time), at most :data:`MAX_CHUNK`."""
    return max(1, min(MAX_CHUNK, n_fabrics // (8 * max(1, n_workers))))


def _merge(core: dict, preview: dict | None) -> dict:
    if preview is None:
        return core
    for s in RENDER_STEPS:
        if s in preview.get("steps", {}):
            core["steps"][s] = preview["steps"][s]
    if preview.get("status") == "failed" and core.get("status") != "failed":
        core.update(status="failed", error=preview.get("error"), failed_step=preview.get("failed_step"))
    core["seconds"] = core.get("seconds", 0.0) + preview.get("seconds", 0.0)
    return core


def _classify(rec: dict) -> str:
    if rec["status"] == "failed":
        return "failed"
    statuses = [s["status"] for s in rec["steps"].values()]
    return "skipped" if statuses and all(s in ("skipped", "unavailable") for s in statuses) else "done"


def _preview_possible(rec: dict) -> bool:
    return rec["status"] != "failed" or rec["steps"].get("fit", {}).get("status") in ("done", "skipped")


def run_batch(catalog, out, steps=DEFAULT_STEPS, workers: int | None = None, scheduler=None, retries: int = 2,
              dashboard: bool | str = False, progress=None, storage_options: dict | None = None,
              settings: dict | None = None, worker_env_extra: dict | None = None,
              write_summary: bool = True, chunk: int | None = None,
              task_timeout: float | None = DEFAULT_TASK_TIMEOUT) -> BatchResult:
    """Process every fabric of ``catalog`` into ``out`` (see the module docstring).

    Parameters
    ----------
    catalog : path, URL, or list of Fabric
        A catalogue CSV or folder (:func:`kesbrdf.batch.catalog.read_catalog`).
    out : path or fsspec URL
        Output root; each fabric writes ``out/<id>/<step>/``.
    steps : iterable of str
        Steps to run; the steps they need are added (:func:`kesbrdf.batch.steps.closure`).
    workers : int, optional
        Size of the local cluster (default: the number of cores); 0 runs serially here.
    scheduler : str or distributed.Client, optional
        Use an existing cluster instead of starting one.
    retries : int
        Retries of a task that failed for a reason other than its input.
    progress : callable(event: dict), optional
        Called with ``{"event": "start", "total", "dashboard", "workers"}`` and, per
        finished fabric, ``{"event": "fabric", "record", "counts"}``.
    settings : dict, optional
        Batch-wide step settings, e.g. ``{"preview": {"spp": 8}}``.
    chunk : int, optional
        Fabrics per core task (default :func:`auto_chunk`); renders are one per task.
    task_timeout : float, optional
        Seconds one step of one fabric may run (default
        :data:`~kesbrdf.batch.runner.DEFAULT_TASK_TIMEOUT`); a step past it is killed
        and the fabric fails with the reason.  None or 0: no limit, and the steps run
        in the worker (or this) process itself.

    Returns
    -------
    BatchResult
    """
    t0 = time.perf_counter()
    steps = tuple(steps)
    all_steps = closure(steps)
    if isinstance(catalog, (list, tuple)):  # Fabric objects from Python: the id check of a catalogue file
        fabrics = [dataclasses.replace(f, error=f.error or check_id(f.id)) for f in catalog]
    else:
        fabrics = read_catalog(catalog, storage_options)
    store = Store(out, storage_options)
    settings = dict(settings or {})
    core_steps = tuple(s for s in all_steps if s not in RENDER_STEPS)
    want_render = any(s in all_steps for s in RENDER_STEPS)
    counts = {"done": 0, "failed": 0, "skipped": 0, "total": len(fabrics)}
    notes: list[str] = []
    records: dict[str, dict] = {}

    def finish(rec):
        counts[_classify(rec)] += 1
        records[rec["id"]] = rec
        if progress:
            progress({"event": "fabric", "record": rec, "counts": dict(counts)})

    if workers is None:
        workers = os.cpu_count() or 1
    dash_link = None
    if scheduler is None and workers == 0:
        if progress:
            progress({"event": "start", "total": len(fabrics), "dashboard": None, "workers": 0})
        for fab in fabrics:
            for attempt in range(1, retries + 2):
                rec = run_chunk([fab], store.url, storage_options, all_steps, settings, task_timeout)[0]
                if rec["status"] != "transient":
                    break
            if rec["status"] == "transient":
                rec = _transient_record(fab, rec["error"], rec.get("failed_step") or "unknown", attempt)
            finish(rec)
        n_workers = 0
    else:
        n_workers, dash_link = _run_dask(fabrics, store, storage_options, core_steps, all_steps, want_render,
                                         settings, workers, scheduler, retries, dashboard, worker_env_extra,
                                         progress, finish, notes, chunk, task_timeout)
    store.sweep([f.id for f in fabrics])
    ordered = [records[f.id] for f in fabrics]
    result = BatchResult(out=store.display(), records=ordered, counts=counts, seconds=time.perf_counter() - t0,
                         notes=notes, dashboard=dash_link, workers=n_workers)
    if write_summary:
        from kesbrdf.batch.summary import write_summary as _write

        result.summary = _write(store, ordered, all_steps, {f.id: f.meta for f in fabrics})
    return result


@contextlib.contextmanager
def _engine_client(scheduler, workers: int, **cluster_kwargs):
    """``(client, scheduler_info)`` of the engine's cluster, the worker plugin registered.

    No ``scheduler`` starts :func:`start_local_cluster` (``workers``, ``cluster_kwargs``);
    an address is connected to; a ``distributed.Client`` is used and left open.  What
    was started or connected here is closed on exit.
    """
    from distributed import Client

    cluster = None
    own_client = True
    if scheduler is None:
        cluster = start_local_cluster(workers, **cluster_kwargs)
        client = Client(cluster)
    elif isinstance(scheduler, str):
        client = Client(scheduler)
    else:
        client, own_client = scheduler, False
    try:
        info = client.scheduler_info()
        n_workers = len(info.get("workers", {}))
        try:
            client.register_plugin(_worker_plugin(worker_env(max(1, n_workers))))
        except AttributeError:  # pragma: no cover - older distributed
            client.register_worker_plugin(_worker_plugin(worker_env(max(1, n_workers))))
        yield client, info
    finally:
        if own_client:
            client.close()
        if cluster is not None:
            cluster.close()


def _run_dask(fabrics, store, storage_options, core_steps, all_steps, want_render, settings, workers, scheduler,
              retries, dashboard, env_extra, progress, finish, notes, chunk, task_timeout):
    from distributed import KilledWorker, as_completed

    with _engine_client(scheduler, workers, dashboard=dashboard, env=env_extra) as (client, info):
        n_workers = len(info.get("workers", {}))
        render_ok = any((w.get("resources") or {}).get("render") for w in info.get("workers", {}).values())
        dash_link = client.dashboard_link if dashboard else None
        if want_render and not render_ok:
            notes.append("preview skipped: no worker has the 'render' resource (Mitsuba + libLLVM)")
        if progress:
            progress({"event": "start", "total": len(fabrics), "dashboard": dash_link, "workers": n_workers})
        render_steps = tuple(s for s in all_steps if s in RENDER_STEPS)
        size = chunk or auto_chunk(len(fabrics), n_workers)
        token = uuid.uuid4().hex[:8]
        by_key: dict[str, tuple] = {}
        attempts: dict[tuple, int] = {}
        core: dict[str, dict] = {}
        ac = as_completed()
        counter = [0]

        def submit(group, kind):
            for fab in group:
                attempts[(kind, fab.id)] = attempts.get((kind, fab.id), 0) + 1
            counter[0] += 1
            key = f"kesbrdf-{kind}-{group[0].id}-{token}-{counter[0]}"
            steps = core_steps if kind == "core" else render_steps
            extra = {} if kind == "core" else {"resources": {"render": 1}}
            fut = client.submit(run_chunk, list(group), store.url, storage_options, steps, settings, task_timeout,
                                key=key, pure=False, **extra)
            by_key[fut.key] = (list(group), kind)
            ac.add(fut)

        def done_core(rec):
            if want_render and render_ok and _preview_possible(rec):
                core[rec["id"]] = rec
                submit([fab_by_id[rec["id"]]], "render")
                return
            if want_render:
                for s in render_steps:
                    rec["steps"][s] = {"status": "unavailable" if not render_ok else "blocked",
                                       "seconds": 0.0, "result": {}, "outputs": {}}
            finish(rec)

        fab_by_id = {f.id: f for f in fabrics}
        for group in chunks(fabrics, size, n_workers):
            submit(group, "core")
        for fut in ac:
            group, kind = by_key.pop(fut.key)
            try:
                recs = fut.result()
            except KilledWorker as exc:  # its workers kept dying: resubmit, one fabric per task
                recs = [{"id": f.id, "status": "transient", "error": f"KilledWorker: {exc}"} for f in group]
            except Exception as exc:  # e.g. a fabric that cannot be sent to a worker
                recs = [{"id": f.id, "status": "transient", "error": f"{type(exc).__name__}: {exc}"} for f in group]
            finally:
                fut.release()
            again = []
            for rec in recs:
                fab = fab_by_id[rec["id"]]
                if rec["status"] == "transient":
                    n = attempts[(kind, fab.id)]
                    if n <= retries:
                        again.append(fab)
                        continue
                    step = rec.get("failed_step") or ("preview" if kind == "render" else "unknown")
                    rec = _transient_record(fab, rec["error"], step, n)
                if kind == "core":
                    done_core(rec)
                else:
                    finish(_merge(core.pop(fab.id), rec))
            for fab in again:
                submit([fab], kind)
        return n_workers, dash_link


def run_tasks(fn, tasks: list, workers: int | None = None, scheduler=None, retries: int = 2, progress=None,
              name: str = "task") -> list:
    """``[fn(*args) for args in tasks]`` on the batch engine's cluster, results in task order.

    The engine for work that is not a catalogue of fabrics (the synthetic fabric library
    of :mod:`kesbrdf.batch.fabric_library`): ``workers=0`` runs serially here; no
    ``scheduler`` starts :func:`start_local_cluster` (spawned single-threaded worker
    processes, no render resource); ``scheduler`` may be an address or a
    ``distributed.Client`` (left open).  A task that raises is resubmitted up to
    ``retries`` times, then its exception propagates.  ``progress(event)`` is called
    with ``{"event": "start", "total", "workers"}`` and, per finished task,
    ``{"event": "task", "index", "result", "done", "total"}``.
    """
    tasks = [tuple(t) for t in tasks]
    results: list = [None] * len(tasks)
    if workers is None:
        workers = os.cpu_count() or 1
    if scheduler is None and workers == 0:
        if progress:
            progress({"event": "start", "total": len(tasks), "workers": 0})
        for k, args in enumerate(tasks):
            for attempt in range(retries + 1):
                try:
                    results[k] = fn(*args)
                    break
                except Exception:  # noqa: BLE001 - retried like a Dask task, then raised
                    if attempt == retries:
                        raise
            if progress:
                progress({"event": "task", "index": k, "result": results[k], "done": k + 1, "total": len(tasks)})
        return results
    from distributed import as_completed

    with _engine_client(scheduler, workers, render=False) as (client, info):
        n_workers = len(info.get("workers", {}))
        if progress:
            progress({"event": "start", "total": len(tasks), "workers": n_workers})
        token = uuid.uuid4().hex[:8]
        index: dict[str, int] = {}
        attempts = [0] * len(tasks)
        ac = as_completed()

        def submit(k):
            attempts[k] += 1
            fut = client.submit(fn, *tasks[k], key=f"kesbrdf-{name}-{k}-{token}-{attempts[k]}", pure=False)
            index[fut.key] = k
            ac.add(fut)

        for k in range(len(tasks)):
            submit(k)
        done = 0
        for fut in ac:
            k = index.pop(fut.key)
            try:
                results[k] = fut.result()
            except Exception:  # noqa: BLE001 - a crashed or killed task: again, while retries last
                if attempts[k] <= retries:
                    submit(k)
                    continue
                raise
            finally:
                fut.release()
            done += 1
            if progress:
                progress({"event": "task", "index": k, "result": results[k], "done": done, "total": len(tasks)})
        return results
