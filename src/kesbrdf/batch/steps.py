"""The per-fabric steps: each a pure function of its input files and parameters.

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
fit        ingest                          ``model.kes.json``
validate   ingest, fit                     ``validation.json`` (round trip, leave-one-
                                           orientation-out, reference when given)
report     ingest, fit, validate           ``report.html`` (the paper's figures)
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
#: Preview render settings (small and fast: one tile of the contact sheet).
PREVIEW_DEFAULTS = {"scene": "sphere", "spp": 16, "resolution": [128, 96],
                    "colourway_spp": 4, "colourway_resolution": [64, 48], "colourways": 6}


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
        return {k: o.get(k) for k in ("kind", "orientations", "fallback", "body", "interpolation", "warp_deg")}
    if step == "validate":
        return {k: o.get(k) for k in ("reference", "reference_params", "mapping", "fallback")}
    if step == "report":
        return {"reference": o.get("reference"), "reference_params": o.get("reference_params"),
                "mapping": o.get("mapping") or "deviation"}
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
    """Fit one measurement with the fit options of a catalogue row: :func:`kesbrdf.fit`.

    ``kind`` (default ``auto``: the kind that uses every row, docs/models.md) and the
    options the row gives (orientations, fallback, body, interpolation, warp_deg) go to
    :func:`kesbrdf.fit`; options left empty keep the library defaults.  The held-out
    comparison with the woven-cloth prior is off in batches (``compare=False``: it costs a
    few prior fits per fabric); a catalogue that wants the prior names ``kind=fibre-prior``.
    """
    import kesbrdf

    kind = params.get("kind") or "auto"
    options = {k: params[k] for k in ("orientations", "fallback", "body", "interpolation", "warp_deg")
               if params.get(k) not in (None, "")}
    model, _report = kesbrdf.fit(m, kind=kind, compare=False, **options)
    return model


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _write_json(path: Path, doc) -> None:
    write_text(path, json.dumps(doc, indent=1, sort_keys=True, default=float) + "\n")


def is_manifest(path: Path) -> bool:
    from kesbrdf.io.files import open_regular

    with open_regular(path) as fh:  # a FIFO or a device is refused, never read
        head = fh.read(256).decode("utf-8", "replace").lstrip("\ufeff").lstrip()
    return head.startswith("# kesbrdf-manifest")


def input_files(path: Path) -> list[Path]:
    """Every file the ingest step reads: the input, and a manifest's frames."""
    if not is_manifest(path):
        return [path]
    from kesbrdf.measure.acquisition.manifest import read_manifest

    man = read_manifest(path)
    return [path, *sorted({row.path for row in man.rows})]


# -- the steps ------------------------------------------------------------------------
def step_ingest(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.io.files import read_regular

    src = Path(inputs["input"])
    if is_manifest(src):
        from kesbrdf.measure.acquisition.ingest import ingest
        from kesbrdf.io.measurement_csv import write_measurement

        res = ingest(src, saturation=params.get("saturation", "reject"))
        write_measurement(out / "measurement.csv", res.measurement)
        counts = res.counts()
        _write_json(out / "ingest.json", {"counts": counts,
                                          "frames": [r.__dict__ for r in res.summary if r.status != "used"]})
        return {"source": "manifest", "n_samples": len(res.measurement), "frames": counts}
    from kesbrdf.io.measurement_csv import parse_measurement

    data = read_regular(src)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise KesbrdfError(f"{src}: expected a measurement CSV (UTF-8 text), got binary data") from None
    m = parse_measurement(text, source=str(src))
    write_bytes(out / "measurement.csv", data)
    return {"source": "csv", "n_samples": len(m)}


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
    from kesbrdf.io.model_file import load_model as load

    return load(inputs["fit/model.kes.json"])


def step_fit(inputs: dict, params: dict, out: Path) -> dict:
    m = _read_m(inputs)
    model = fit_model(m, params)
    model.save(out / "model.kes.json")
    d = getattr(model, "diagnostics", {}) or {}
    return {
        "kind": model.kind,
        "n_samples": len(m),
        "channels": list(model.channels),
        "floored": len(d.get("floored", []) or []),
        "fallback_gamma": len(d.get("fallback_gamma_deg", []) or []),
    }


def step_validate(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.validate.compare import HELD_OUT_DEG, leave_one_orientation_out, validate

    m = _read_m(inputs)
    model = _load_model(inputs)
    doc = {"round_trip": validate(model, m, params.get("mapping"))}
    result = {"fit_nrmse": _finite(doc["round_trip"]["metrics"]["all"]["nrmse"]),
              "fit_rmse": _finite(doc["round_trip"]["metrics"]["all"]["rmse"])}
    if model.fitter_name == "kes":  # the KES interpolation's own check (the kes fitter made it)
        try:
            loo = leave_one_orientation_out(m, mapping=params.get("mapping") or "deviation",
                                            fallback=params.get("fallback") or "log")
        except KesbrdfError as exc:
            loo = {"error": str(exc)}
        doc["leave_one_orientation_out"] = loo
        errs = [v["metrics"]["all"]["nrmse"] for v in loo.values() if isinstance(v, dict) and v.get("possible")]
        result["loo_nrmse"] = _finite(max(errs)) if errs else None
    ref = make_fabric_reference(params.get("reference"), params.get("reference_params"))
    if ref is not None:
        from kesbrdf.measure.gonio import measure

        protocol = "dense" if '"protocol": "dense"' in str(m.metadata.get("generator", "")) else "paper"
        held = measure(ref, protocol=protocol, orientations_deg=HELD_OUT_DEG)
        doc["reference"] = {"name": params.get("reference"), "params": params.get("reference_params"),
                            "held_out_orientations_deg": list(HELD_OUT_DEG),
                            "held_out": validate(model, held, params.get("mapping"))}
        result["ref_nrmse"] = _finite(doc["reference"]["held_out"]["metrics"]["all"]["nrmse"])
    _write_json(out / "validation.json", doc)
    return result


def step_report(inputs: dict, params: dict, out: Path) -> dict:
    from kesbrdf.plotting.report import collect, write_report

    m = _read_m(inputs)
    model = _load_model(inputs)
    ref = make_fabric_reference(params.get("reference"), params.get("reference_params"))
    metrics, diagnostics = collect(model, m, ref, mapping=params.get("mapping") or "deviation")
    sample = (getattr(model, "input_info", None) or {}).get("sample") or m.metadata.get("sample") or "fabric"
    opts = {name: {"mapping": params.get("mapping") or "deviation"} for name in ("3a", "3b", "4", "6")}
    write_report(out / "report.html", model, measurement=m, reference=ref, metrics=metrics,
                 diagnostics=diagnostics, title=f"kesbrdf report: {sample}", figure_options=opts)
    return {"report": "report.html"}


def step_export(inputs: dict, params: dict, out: Path) -> dict:
    import importlib
    import shutil

    import kesbrdf.export as ex

    import time

    model = _load_model(inputs)
    if params["formats"] and os.environ.get("KESBRDF_DRJIT_THREADS"):
        drjit_threads()  # some writers build Mitsuba warps
    done, failed, seconds = {}, {}, {}
    for fmt in params["formats"]:
        name = params["modules"][fmt]  # as resolved when the key was made (not this process's registry)
        t0 = time.perf_counter()
        try:  # a format whose optional dependency is missing fails alone
            module = importlib.import_module(name if "." in name else f"kesbrdf.export.{name}")
            exts = tuple(getattr(module, "EXTENSIONS", ()) or ()) or (f".{fmt}",)
            # one folder per format: formats share endings (.bsdf) and write side files
            (out / fmt).mkdir()
            target = out / fmt / f"model{exts[0]}"
            if hasattr(ex, "export"):
                # the framework looks formats up by name: lend it the module the step's key
                # names (a step process, or a Dask worker, may not share the caller's registry)
                before = ex.FORMATS.get(fmt)
                ex.FORMATS[fmt] = name
                try:
                    res = ex.export(model, fmt, target)
                finally:
                    if before is None:
                        ex.FORMATS.pop(fmt, None)
                    else:
                        ex.FORMATS[fmt] = before
            else:  # before the export framework lands: call the format module directly
                res = module.export(model, target)
        except (KesbrdfError, ImportError) as exc:
            failed[fmt] = " ".join(str(exc).split())
            shutil.rmtree(out / fmt, ignore_errors=True)  # no partial files of a failed format
            continue
        finally:
            seconds[fmt] = time.perf_counter() - t0
        info = res.to_json() if hasattr(res, "to_json") else {"paths": [str(target)]}
        info["paths"] = [os.path.relpath(p, out) for p in info.get("paths", [])]
        done[fmt] = info
    _write_json(out / "export.json", {"formats": done, "failed": failed})
    note = None if params["formats"] else "no export formats installed (kesbrdf.export.FORMATS is empty)"
    # timings go to the manifest's result, never into files (outputs stay bit-reproducible)
    return {"formats": sorted(done), "failed": failed, "note": note, "seconds": seconds,
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
    from kesbrdf.render import scenes
    from kesbrdf.render.colourways import DEFAULT_COLOURWAYS, render_colourways

    model_path = inputs["fit/model.kes.json"]
    opts = scenes.RenderOptions(spp=int(params["spp"]), resolution=tuple(params["resolution"]))
    scenes.render_still(model_path, params["scene"], out / "preview.png", opts)
    copts = scenes.RenderOptions(spp=int(params["colourway_spp"]), resolution=tuple(params["colourway_resolution"]))
    n = int(params["colourways"])
    render_colourways(model_path, out / "colourways.png", copts, scene=params["scene"],
                      colourways=DEFAULT_COLOURWAYS[:n], columns=min(n, 3))
    return {"preview": "preview.png", "colourways": "colourways.png", "drjit_threads": threads or None}


STEP_FUNCTIONS = {
    "ingest": step_ingest,
    "fit": step_fit,
    "validate": step_validate,
    "report": step_report,
    "export": step_export,
    "preview": step_preview,
}
