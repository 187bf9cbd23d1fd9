"""The batch stage of ``kesbrdf demo``: a small simulated library on a local Dask cluster."""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_demo_batch", "DEMO_FABRICS", "DEMO_BROKEN", "DEMO_KIND"]

#: 10 good + 2 deliberately broken fabrics = the 12 of the demo
DEMO_FABRICS = 10
DEMO_BROKEN = 2
#: Export formats of the demo batch: the BRDF Explorer file (a baked table, ~0.1 s and
#: 0.4 MB a fabric).  The analytic fits (glTF, MaterialX, USD) take 20-50 s and the RGL
#: tensors 22-44 MB a fabric; ``kesbrdf batch`` exports every format unless told otherwise,
#: and the demo exports every format for its own fabric (out/demo/exports).
DEMO_EXPORT_FORMATS = ("brdf-explorer",)
#: The demo library's ``kind`` column: the paper protocol's KES fit, asked for.  ``kesbrdf
#: fit``'s rule (an empty column, what ``kesbrdf batch`` does on a user's catalogue)
#: compares each fabric with the woven-cloth prior by leave-one-orientation-out refits,
#: ~8 s of CPU a fabric, 80 s for the ten: 40 % of the demo's CPU budget for a step
#: that shows orchestration at library scale.  The summary's ``kind`` column shows the
#: kind and each ``fit_report.json`` says it was asked for (docs/decisions.md, "A batch
#: fits by kesbrdf fit's rule").
DEMO_KIND = "kes"


def run_demo_batch(out, quick: bool = False, workers: int = 2, progress=None, scheduler=None):
    """Simulate the library into ``out/library`` and batch it into ``out/results``.

    ``scheduler``: an existing cluster (default: a local one of ``workers`` processes).
    Steps: ingest, fit, validate, export and preview (``quick``: no preview).  The
    per-fabric HTML report is left out to keep the demo short (the demo's own report
    covers the embedded sample); ``kesbrdf batch`` runs it by default.  Returns the
    :class:`~kesbrdf.batch.engine.BatchResult`.
    """
    from kesbrdf.batch.engine import run_batch
    from kesbrdf.batch.library import simulate_library

    out = Path(out)
    catalog = simulate_library(DEMO_FABRICS, out / "library", seed=2026, broken=DEMO_BROKEN, kind=DEMO_KIND)
    steps = ("ingest", "fit", "validate", "export") + (() if quick else ("preview",))
    result = run_batch(catalog, out / "results", steps=steps, workers=workers, scheduler=scheduler,
                       settings={"export": {"formats": list(DEMO_EXPORT_FORMATS)}})
    if progress is not None:
        c = result.counts
        progress(f"batch: {c['done'] + c['skipped']} ok, {c['failed']} failed (as intended) in {result.seconds:.1f} s; "
                 f"contact sheet {result.summary.get('index')}")
    return result
