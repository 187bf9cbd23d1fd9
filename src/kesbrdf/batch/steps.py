"""The per-fabric steps of a batch: the pipeline's steps (:mod:`kesbrdf.pipeline`) on files.

Each batch step reads its inputs from files, calls the pipeline step of the same name
(the one ``kesbrdf demo`` runs: the same fit rule as ``kesbrdf fit``, the same
validation, report, exports and preview) and writes its outputs to files; the
engine adds the skip rule, the cache and Dask on top (docs/batch.md, docs/pipeline.md).

A step function ``step(inputs, params, out) -> result`` reads the local files named in
``inputs`` (``{"<upstream step>/<file>": Path}``, or ``{"input": Path}`` for
``ingest``), writes its files into the empty local folder ``out`` and returns a small
JSON-able dict of numbers for the summary.  It never looks at the clock, the
hostname or anything else that is not an input, so equal inputs and parameters give
equal outputs (the basis of the skip rule, :mod:`kesbrdf.batch.manifest`).

=========  ==============================  ==========================================
step       needs                           writes
=========  ==============================  ==========================================
ingest     the catalogue input             ``measurement.csv`` (manifests: frames →
                                           values; CSVs: the bytes as given, checked)
fit        ingest                          ``model.kes.json`` (the chosen model,
                                           any kind) and ``fit_report.json``
validate   ingest, fit                     ``validation.json`` (round trip, leave-one-
                                           orientation-out, reference when given)
report     ingest, fit, validate           ``report.html`` (the paper's figures;
                                           metrics from ``validation.json``)
export     fit                             ``<format>/model.<ext>`` per format in
                                           ``export.FORMATS``, plus ``export.json``
preview    fit                             ``preview.png`` and ``colourways.png``
                                           (Mitsuba; runs on ``render`` workers)
=========  ==============================  ==========================================
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from kesbrdf._atomic import write_bytes, write_text
from kesbrdf.errors import KesbrdfError
from kesbrdf.pipeline.outputs import PREVIEW_DEFAULTS  # preview render settings (one contact-sheet tile)

__all__ = ["STEPS", "DEPENDS", "STEP_FUNCTIONS", "RENDER_STEPS", "closure", "step_params",
           "fit_model", "make_fabric_reference", "PREVIEW_DEFAULTS"]

STEPS = ("ingest", "fit", "validate", "report", "export", "preview")
DEPENDS = {
    "ingest": (),
    "fit": ("ingest",),
    "validate": ("ingest", "fit"),
    "report": ("ingest", "fit", "validate"),
    "export": ("fit",),
    "preview": ("fit",),
}
RENDER_STEPS = ("preview",)


def closure(steps) -> tuple[str, ...]:
    """``steps`` plus everything they need, in pipeline order."""
    want = set()

    def add(s):
        if s not in DEPENDS:
            raise KesbrdfError(f"unknown step {s!r}; expected some of {', '.join(STEPS)}")
        want.add(s)
        for d in DEPENDS[s]:
            add(d)

    for s in steps:
        add(s)
    return tuple(s for s in STEPS if s in want)


def step_params(step: str, options: dict, settings: dict | None = None) -> dict:
    """The parameters of ``step`` for a fabric's options (only what the step reads)."""
    o = options
    settings = settings or {}
    if step == "ingest":
        return {"saturation": "reject"}
    if step == "fit":
        from kesbrdf.pipeline import FIT_OPTION_NAMES

        # "rule": the fit rule of kesbrdf fit (compare with the prior); part of the key,
        # so models fitted by the older batch rule (no comparison) are refitted
        return {"rule": "kesbrdf-fit", **{k: o.get(k) for k in ("kind",) + FIT_OPTION_NAMES}}
    if step == "validate":
        return {k: o.get(k) for k in ("reference", "reference_params", "mapping", "fallback")}
    if step == "report":
        return {"reference": o.get("reference"), "reference_params": o.get("reference_params"),
                "mapping": o.get("mapping")}  # None: the model's own
    if step == "export":
        from kesbrdf.export import FORMATS

        wanted = settings.get("export", {}).get("formats")  # None: every installed format
        if wanted is not None:
            unknown = sorted(set(wanted) - set(FORMATS))
            if unknown:
                raise KesbrdfError(f"export formats: unknown {', '.join(map(repr, unknown))}; "
                                   f"installed: {', '.join(FORMATS) or '(none)'}")
        fmts = sorted(f for f in FORMATS if wanted is None or f in wanted)
        # formats whose module cannot be imported here (a missing optional dependency) are
        # part of the key: installing the dependency reruns the export step
        return {"formats": fmts, "modules": {k: FORMATS[k] for k in fmts},
                "unavailable": [k for k in fmts if not _importable(FORMATS[k])]}
    if step == "preview":
        return {**PREVIEW_DEFAULTS, **settings.get("preview", {})}
    raise KesbrdfError(f"unknown step {step!r}")  # pragma: no cover


# -- helpers ------------------------------------------------------------------------
def _importable(name: str) -> bool:
    import importlib

    try:
        importlib.import_module(name if "." in name else f"kesbrdf.export.{name}")
    except ImportError:
        return False
    return True


def make_fabric_reference(name: str | None, params: dict | None = None):
    """The fabric's ground-truth BRDF: a ``kesbrdf simulate`` reference name, or
    ``sadeghi:<preset>`` for any Sadeghi et al. 2013 preset (Table II)."""
    if not name:
        return None
    if name.startswith("sadeghi:"):
        from kesbrdf.references import sadeghi2013

        return sadeghi2013.Sadeghi2013(preset=name.split(":", 1)[1], **(params or {}))
    from kesbrdf.references.registry import make_reference

    return make_reference(name, json.dumps(params) if params else None)


def fit_model(m, params: dict):
    """Fit one measurement with the fit options of a catalogue row, by the rule of
    ``kesbrdf fit`` (:func:`kesbrdf.pipeline.fit`): ``kind`` (default ``auto``, which
    compares the row-based choice with the woven-cloth prior unless an option is given)
    and the options the row sets; options left empty keep the library defaults.  So a
    fabric gets the same model in a batch as from the command.  Returns the
    :class:`~kesbrdf.pipeline.Fitted`.
    """
    from kesbrdf.pipeline import FitSpec, fit

    return fit(m, FitSpec.from_row(params))


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _write_json(path: Path, doc) -> None:
    write_text(path, json.dumps(doc, indent=1, sort_keys=True, default=float) + "\n")


def is_manifest(path: Path) -> bool:
    from kesbrdf.pipeline import is_manifest as _is_manifest

    return _is_manifest(path)


def input_files(path: Path) -> list[Path]:
    """Every file the ingest step reads: the input, and a manifest's frames."""
    if not is_manifest(path):
        return [path]
    from kesbrdf.measure.acquisition.manifest import read_manifest

    man = read_manifest(path)
    return [path, *sorted({row.path for row in man.rows})]


# -- the steps ------------------------------------------------------------------------
def step_ingest(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.pipeline import ingest

    src = Path(inputs["input"])
    got = ingest(src, saturation=params.get("saturation", "reject"))
    if got.source == "manifest":
        write_measurement(out / "measurement.csv", got.measurement)
        _write_json(out / "ingest.json", {"counts": got.counts, "frames": got.dropped})
        return {"source": "manifest", "n_samples": len(got.measurement), "frames": got.counts}
    write_bytes(out / "measurement.csv", got.raw)  # the bytes as given (checked by ingest)
    return {"source": "csv", "n_samples": len(got.measurement)}


def _read_m(inputs):
    """The ingested measurement, named after the catalogue input (not the output folder,
    so a model does not depend on where OUT is; for a CSV input the bytes and line
    numbers are the input's own)."""
    import hashlib

    from kesbrdf.io.measurement_csv import parse_measurement

    data = Path(inputs["ingest/measurement.csv"]).read_bytes()
    name = inputs.get("source") or "ingest/measurement.csv"
    return parse_measurement(data.decode("utf-8-sig"), source=str(name), sha256=hashlib.sha256(data).hexdigest())


def _load_model(inputs):
    from kesbrdf.io.model_file import load_model

    return load_model(inputs["fit/model.kes.json"])


def _fitted(inputs):
    """The fit step's model as a :class:`~kesbrdf.pipeline.Fitted` (model, selection, hash)."""
    from kesbrdf.fitting import FitReport
    from kesbrdf.pipeline import FitSpec, Fitted, model_sha256

    model = _load_model(inputs)
    rec = (model.diagnostics or {}).get("fit_report") if isinstance(model.diagnostics, dict) else None
    rec = rec if isinstance(rec, dict) else {"kind": model.kind, "fitter": model.kind, "reason": "read from a file",
                                             "rows_total": 0, "rows_used": 0}
    report = FitReport(**{k: rec[k] for k in FitReport.__dataclass_fields__ if k in rec})
    return Fitted(model, report, FitSpec(), model_sha256(model) or "")


def step_fit(inputs: dict, params: dict, out: Path) -> dict:
    m = _read_m(inputs)
    fitted = fit_model(m, params)
    fitted.save(out / "model.kes.json")
    _write_json(out / "fit_report.json", {"model_sha256": fitted.sha256, **fitted.selection()})
    d = getattr(fitted.model, "diagnostics", {}) or {}
    return {
        "kind": fitted.kind,
        "n_samples": len(m),
        "channels": list(fitted.model.channels),
        "floored": len(d.get("floored", []) or []),
        "fallback_gamma": len(d.get("fallback_gamma_deg", []) or []),
        "reason": fitted.report.reason,
    }


def step_validate(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.pipeline import validate

    m = _read_m(inputs)
    ref = make_fabric_reference(params.get("reference"), params.get("reference_params"))
    # the protocol of the held-out re-measurement is read from the geometry (pipeline.protocol_of)
    v = validate(_fitted(inputs), m, ref, mapping=params.get("mapping"), fallback=params.get("fallback") or "log",
                 baselines=False)
    doc = {"round_trip": v.round_trip}
    if v.leave_one_orientation_out is not None:
        doc["leave_one_orientation_out"] = v.leave_one_orientation_out
    if v.held_out is not None:
        doc["reference"] = {"name": params.get("reference"), "params": params.get("reference_params"),
                            "held_out_orientations_deg": v.held_out["held_out_orientations_deg"],
                            "held_out": {k: x for k, x in v.held_out.items() if k != "held_out_orientations_deg"}}
    _write_json(out / "validation.json", doc)
    return v.numbers()


def step_report(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.pipeline.outputs import report, report_inputs
    from kesbrdf.validate.diagnostics import diagnose

    m = _read_m(inputs)
    fitted = _fitted(inputs)
    ref = make_fabric_reference(params.get("reference"), params.get("reference_params"))
    mapping = params.get("mapping")  # None: the model's own (kes: the mapping it records)
    metrics = json.loads(Path(inputs["validate/validation.json"]).read_text())
    sample = (getattr(fitted.model, "input_info", None) or {}).get("sample") or m.metadata.get("sample") or "fabric"
    opts = {name: {"mapping": mapping} for name in ("3a", "3b", "4", "6")}
    report(report_inputs(fitted, m, reference=ref, metrics=metrics, diagnostics=diagnose(fitted.model),
                         title=f"kesbrdf report: {sample}", figure_options=opts), out / "report.html")
    return {"report": "report.html"}


def step_export(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.pipeline.outputs import export

    model = _load_model(inputs)
    if params["formats"] and os.environ.get("KESBRDF_DRJIT_THREADS"):
        drjit_threads()  # some writers build Mitsuba warps
    # the module each format's key names (a step process, or a Dask worker, may not share
    # the caller's registry); one folder per format
    got = export(model, out, params["formats"], stem="model", modules=params["modules"])
    done = {}
    for fmt, res in got.results.items():
        info = res.to_json()
        info["paths"] = [os.path.relpath(p, out) for p in info.get("paths", [])]
        done[fmt] = info
    _write_json(out / "export.json", {"formats": done, "failed": got.failed})
    note = None if params["formats"] else "no export formats installed (kesbrdf.export.FORMATS is empty)"
    # timings go to the manifest's result, never into files (outputs stay bit-reproducible)
    return {"formats": sorted(done), "failed": got.failed, "note": note, "seconds": got.seconds,
            "paths": [p for v in done.values() for p in v["paths"]]}


def drjit_threads(required: bool = False) -> int | None:
    """Cap Dr.Jit's thread pool at ``$KESBRDF_DRJIT_THREADS`` (cores per worker).

    Dr.Jit's LLVM backend starts a pool over *all* cores in every process; k workers per
    node would run k × cores threads.  Called before the steps that may run Dr.Jit
    (export formats that build Mitsuba warps, the preview render).  Returns the count
    set, or None (not set, or Mitsuba absent and not ``required``).
    """
    threads = int(os.environ.get("KESBRDF_DRJIT_THREADS", "0") or 0)
    try:
        from kesbrdf._drjit import import_mitsuba

        _mi, dr = import_mitsuba("the batch preview step")
    except ImportError:
        if required:
            raise
        return None
    if threads > 0:
        dr.set_thread_count(threads)
        return threads
    return None


def step_preview(inputs: dict, params: dict, out: Path) -> dict:
    threads = drjit_threads(required=True)
    from kesbrdf.pipeline.outputs import preview

    got = preview(inputs["fit/model.kes.json"], out, params)
    return {"preview": got.still.name, "colourways": got.colourways.name, "drjit_threads": threads or None}


STEP_FUNCTIONS = {
    "ingest": step_ingest,
    "fit": step_fit,
    "validate": step_validate,
    "report": step_report,
    "export": step_export,
    "preview": step_preview,
}
