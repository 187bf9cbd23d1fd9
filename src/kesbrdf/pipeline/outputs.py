"""The pipeline's steps that write through the views: report, export, preview.

They sit above the views (plotting, export, render) and below batch and the command
line (tests/test_layers.py); the steps up to validation are in :mod:`kesbrdf.pipeline`.
Each takes the one :class:`~kesbrdf.pipeline.Fitted` model (or the file it was saved
to) and returns a typed result; none prints.  docs/pipeline.md.
"""

from __future__ import annotations

import contextlib
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from kesbrdf.errors import KesbrdfError

__all__ = ["report_inputs", "report", "Exported", "export", "Preview", "preview", "PREVIEW_DEFAULTS"]


# -- report -----------------------------------------------------------------------------
def report_inputs(fitted, measurement=None, validated=None, reference=None, **fields):
    """The :class:`~kesbrdf.plotting.report.ReportInputs` of a fitted model: the model,
    its content hash and selection report, and the validation's metrics and diagnostics;
    ``fields`` sets any other field (title, figures, comparisons, looks, ...)."""
    from kesbrdf.plotting.report import ReportInputs

    base = {"model": fitted.model, "measurement": measurement, "reference": reference,
            "model_sha256": fitted.sha256, "selection": fitted.selection()}
    if validated is not None:
        base["metrics"] = validated.metrics()
        base["diagnostics"] = validated.diagnostics
    base.update(fields)
    return ReportInputs(**base)


def report(inputs, path) -> Path:
    """Write the HTML report of ``inputs`` (:class:`~kesbrdf.plotting.report.ReportInputs`) to ``path``."""
    from kesbrdf.plotting.report import write_report

    return write_report(path, inputs)


# -- export -----------------------------------------------------------------------------
@dataclass
class Exported:
    """What :func:`export` wrote.

    ``results``: format → :class:`~kesbrdf.export.ExportResult`; ``failed``: format →
    one-line reason (a missing optional dependency, a model the format cannot hold);
    ``seconds``: wall time per format (for the caller's log, never written into files).
    """

    results: dict = field(default_factory=dict)
    failed: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)

    def main_files(self) -> dict:
        """Format → the main file written."""
        return {fmt: Path(r.paths[0]) for fmt, r in self.results.items()}


@contextlib.contextmanager
def _lent_formats(modules: dict | None):
    """Lend the format registry the modules named in ``modules`` (a batch step's key, made
    in another process, may name a format this process's registry lacks)."""
    import kesbrdf.export as ex

    before = {fmt: ex.FORMATS.get(fmt) for fmt in (modules or {})}
    ex.FORMATS.update(modules or {})
    try:
        yield
    finally:
        for fmt, old in before.items():
            if old is None:
                ex.FORMATS.pop(fmt, None)
            else:
                ex.FORMATS[fmt] = old


def export(fitted, folder, formats=None, *, stem: str = "model", options: dict | None = None,
           modules: dict | None = None, fit_cache_dir=None, progress=None) -> Exported:
    """Export the model in each format into ``folder/<format>/<stem><ending>``.

    Parameters
    ----------
    fitted : Fitted or model
    formats : sequence of str, optional
        Default every registered format (:data:`kesbrdf.export.FORMATS`).
    options : dict, optional
        Format → options; an option the format does not take is left out (so one dict
        can set, e.g., ``fit_grid`` for every analytic format).
    modules : dict, optional
        Format → module name to use (see :func:`_lent_formats`).
    fit_cache_dir : path, optional
        Keep the analytic fits (glTF, glb, MaterialX, USD) on disk here as well as in
        memory: each fit is computed once per model content and shared by the formats
        that need it (:mod:`kesbrdf.export.fit_cache`).
    progress : callable(str), optional
        Called with ``"<format>"`` before each format.

    A format that fails (missing dependency, a model it cannot hold) fails alone: its
    folder is removed and the reason recorded in :attr:`Exported.failed`.
    """
    import inspect

    from kesbrdf.export import export as export_one
    from kesbrdf.export import fit_cache, format_module, format_names

    model = getattr(fitted, "model", fitted)
    folder = Path(folder)
    done = Exported()
    options = options or {}
    cache = fit_cache.cache_in(fit_cache_dir) if fit_cache_dir is not None else contextlib.nullcontext()
    with _lent_formats(modules), cache:
        for fmt in (format_names() if formats is None else formats):
            if progress is not None:
                progress(fmt)
            t0 = time.perf_counter()
            made = not (folder / fmt).exists()
            try:
                module = format_module(fmt)
                ext = (getattr(module, "EXTENSIONS", ()) or (f".{fmt}",))[0]
                accepted = inspect.signature(module.export).parameters
                opts = {k: v for k, v in (options.get(fmt) or options.get("*") or {}).items() if k in accepted}
                # one folder per format: formats share endings (.bsdf) and write side files
                (folder / fmt).mkdir(parents=True, exist_ok=True)
                done.results[fmt] = export_one(model, fmt, folder / fmt / f"{stem}{ext}", **opts)
            except (KesbrdfError, ImportError) as exc:
                done.failed[fmt] = " ".join(str(exc).split())
                if made:
                    shutil.rmtree(folder / fmt, ignore_errors=True)  # no partial files of a failed format
            finally:
                done.seconds[fmt] = time.perf_counter() - t0
    return done


# -- preview ----------------------------------------------------------------------------
#: Preview render settings (one tile of the contact sheet): 256 × 192 in the studio
#: (soft boxes, windows, ACES, exposure metered on the grey card, docs/rendering.md
#: "Studio"), denoised by OIDN when installed, so a satin's highlight can be judged.
PREVIEW_DEFAULTS = {"scene": "sphere", "spp": 16, "resolution": [256, 192],
                    "colourway_spp": 4, "colourway_resolution": [128, 96], "colourways": 6}
#: Below this many pixels a preview is not denoised (OIDN's set-up costs more than a few spp).
PREVIEW_DENOISE_MIN_PIXELS = 128 * 96


@dataclass
class Preview:
    """The preview render and colourway sheet written by :func:`preview`."""

    still: Path
    colourways: Path


def preview(model_path, folder, settings: dict | None = None) -> Preview:
    """Render the saved model (any kind the renderer draws) as a still and a colourway
    sheet into ``folder`` (``preview.png``, ``colourways.png``); ``settings`` overrides
    :data:`PREVIEW_DEFAULTS`."""
    from dataclasses import replace

    from kesbrdf.render import scenes
    from kesbrdf.render.colourways import DEFAULT_COLOURWAYS, render_colourways
    from kesbrdf.render.exposure import meter_exposure

    p = {**PREVIEW_DEFAULTS, **(settings or {})}
    folder = Path(folder)

    def denoise(res):
        return scenes.can_denoise() and int(res[0]) * int(res[1]) >= PREVIEW_DENOISE_MIN_PIXELS

    res = tuple(p["resolution"])
    opts = scenes.RenderOptions(spp=int(p["spp"]), resolution=res, env="studio-hdr", light="studio",
                                tonemap="aces", denoise=denoise(res))
    opts = replace(opts, exposure=meter_exposure(model_path, p["scene"], opts))  # one grey-card reading
    scenes.render_still(model_path, p["scene"], folder / "preview.png", opts)
    cres = tuple(p["colourway_resolution"])
    copts = replace(opts, spp=int(p["colourway_spp"]), resolution=cres, denoise=denoise(cres))
    n = int(p["colourways"])
    render_colourways(model_path, folder / "colourways.png", copts, scene=p["scene"],
                      colourways=DEFAULT_COLOURWAYS[:n], columns=min(n, 3))
    return Preview(folder / "preview.png", folder / "colourways.png")
