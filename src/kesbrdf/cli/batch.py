"""``kesbrdf batch CATALOG -o OUT``: a whole fabric library on a Dask cluster (docs/batch.md)."""

from __future__ import annotations

import math
import time

from kesbrdf.cli._common import check_output, stderr

HELP = "Fit, validate, report, export and preview every fabric of a catalogue on a (local) Dask cluster."


def add_arguments(p):
    p.add_argument("catalog", help="catalogue CSV (id,input,...) or a folder of inputs; path or fsspec URL")
    p.add_argument("-o", "--output", required=True, help="output folder or fsspec URL (OUT/<fabric>/<step>/)")
    p.add_argument("--steps", default="ingest,fit,validate,report,export,preview",
                   help="comma-separated steps; needed steps are added (default: all)")
    p.add_argument("--workers", type=int, default=None,
                   help="local cluster worker processes (default: cores; 0: serial in this process)")
    p.add_argument("--retries", type=int, default=2, help="retries of a transient failure (default 2)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="use an existing Dask cluster")
    p.add_argument("--dashboard", nargs="?", const=True, default=False, metavar="PORT",
                   help="serve the Dask dashboard on 127.0.0.1 (optionally on PORT) and print its address")
    p.add_argument("--preview-spp", type=int, default=None, help="samples per pixel of the preview tile")
    p.add_argument("--export-formats", default=None, metavar="A,B",
                   help="export only these formats (default: every format in kesbrdf.export.FORMATS)")
    p.add_argument("--task-timeout", type=float, default=None, metavar="SECONDS",
                   help="longest one step of one fabric may run before it is killed and the fabric fails "
                        "(default 600; 0: no limit, steps run inside the worker)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


class _Bar:
    """tqdm bar with done / failed / skipped counts; throughput is tqdm's rate."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bar = None
        self.t0 = time.perf_counter()

    def __call__(self, ev):
        if ev["event"] == "start":
            if ev.get("dashboard"):
                stderr(f"dask dashboard: {ev['dashboard']}")
            where = f"{ev['workers']} worker(s)" if ev["workers"] else "serial"
            stderr(f"batch: {ev['total']} fabric(s) on {where}")
            if self.enabled:
                from tqdm import tqdm

                self.bar = tqdm(total=ev["total"], unit="fabric", dynamic_ncols=True, smoothing=0.1)
            return
        c = ev["counts"]
        if self.bar is not None:
            self.bar.set_postfix(done=c["done"], failed=c["failed"], skipped=c["skipped"], refresh=False)
            self.bar.update(1)
        rec = ev["record"]
        if rec["status"] == "failed":
            msg = f"failed {rec['id']} ({rec.get('failed_step')}): {rec['error']}"
            (self.bar.write(msg) if self.bar is not None else stderr(msg))

    def close(self):
        if self.bar is not None:
            self.bar.close()


def run(args) -> int:
    from kesbrdf.batch import run_batch
    from kesbrdf.errors import KesbrdfError

    from kesbrdf.batch.store import is_url

    if not is_url(args.output):
        check_output(args.output, folder=True)
    steps = tuple(s.strip() for s in args.steps.split(",") if s.strip())
    if not steps:
        raise KesbrdfError(f"--steps: expected comma-separated step names, got {args.steps!r}")
    if args.workers is not None and args.workers < 0:
        raise KesbrdfError(f"--workers: expected a count >= 0, got {args.workers}")
    if args.retries < 0:
        raise KesbrdfError(f"--retries: expected a count >= 0, got {args.retries}")
    from kesbrdf.batch.runner import DEFAULT_TASK_TIMEOUT

    timeout = DEFAULT_TASK_TIMEOUT if args.task_timeout is None else args.task_timeout
    if not (timeout >= 0 and math.isfinite(timeout)):
        raise KesbrdfError(f"--task-timeout: expected seconds >= 0 (0: no limit), got {args.task_timeout}")
    dashboard = args.dashboard
    if isinstance(dashboard, str):
        if not dashboard.isdigit():
            raise KesbrdfError(f"--dashboard: expected a port number, got {dashboard!r}")
        dashboard = f"127.0.0.1:{dashboard}"
    if dashboard:
        import importlib.util

        if importlib.util.find_spec("bokeh") is None:
            stderr("note: the Dask dashboard needs bokeh (pip install 'bokeh>=3.1'); running without it")
            dashboard = False
    settings = {"preview": {"spp": args.preview_spp}} if args.preview_spp else {}
    if args.export_formats is not None:
        from kesbrdf.export import FORMATS

        wanted = [f.strip() for f in args.export_formats.split(",") if f.strip()]
        unknown = [f for f in wanted if f not in FORMATS]
        if unknown:
            raise KesbrdfError(f"--export-formats: unknown {', '.join(map(repr, unknown))}; "
                               f"installed: {', '.join(FORMATS) or '(none)'}")
        settings["export"] = {"formats": wanted}
    bar = _Bar(not args.no_progress)
    try:
        result = run_batch(args.catalog, args.output, steps=steps, workers=args.workers, scheduler=args.scheduler,
                           retries=args.retries, dashboard=dashboard, progress=bar, settings=settings,
                           task_timeout=timeout)
    finally:
        bar.close()
    c = result.counts
    rate = c["total"] / result.seconds * 60 if result.seconds > 0 else float("nan")
    for note in result.notes:
        stderr(f"note: {note}")
    stderr(f"batch: {c['done']} done, {c['skipped']} skipped (up to date), {c['failed']} failed of {c['total']} "
           f"in {result.seconds:.1f} s ({rate:.0f} fabrics/min)")
    for name in ("csv", "parquet", "index"):
        if result.summary.get(name):
            stderr(f"wrote {result.summary[name]}")
    return 0
