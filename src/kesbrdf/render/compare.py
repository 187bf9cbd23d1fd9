r"""Reference vs model: the same scene rendered with a reference BRDF and with the KES
model fitted from that reference's virtual measurements, with an error map.

Chain (one call, :func:`compare_render`):

1. ``ref = make_reference(name)`` (:mod:`kesbrdf.render.reference_bsdf`).
2. Measure it with the virtual gonioreflectometer, :func:`kesbrdf.measure.gonio.measure`:

   - ``protocol="paper"``: the paper's 116 in-plane samples (θ_i + θ_r = 90°, 3° steps,
     ψ = 0, 45, 90, 135°), fitted with :func:`kesbrdf.models.kes.fit` (kind ``kes``) and
     rendered by the ``kesbrdf`` plugin (``deviation`` mapping);
   - ``protocol="dense"``: every in-plane (θ_i, θ_r) pair on a 6° grid (900 samples),
     fitted with :func:`kesbrdf.models.halfdiff.fit_halfdiff` (kind ``kes-halfdiff``) and
     rendered by the ``kesbrdf_halfdiff`` plugin (:mod:`kesbrdf.render.halfdiff_bsdf`).

   By default (``models=("default",)``) the measurement is fitted as ``kesbrdf fit`` fits
   it (``kind="auto"``, the default rule of docs/models.md), so the panel shows the model a
   user gets; ``"kes"`` asks for the protocol's KES kind above, and any registered kind
   name for that kind.  The KES fits use ``fallback="log"`` (docs/method.md,
   "Interpolation over orientation") and ``body="auto"``.  With
   ``models=("default", "fibre-prior")`` the same measurement is also fitted with the fibre
   prior times its residual (:meth:`kesbrdf.models.fibre_prior.FibrePriorModel.fit_measurement`,
   kind ``fibre-prior``: a KES residual table on the paper protocol, a half/difference
   one on the dense grid) and rendered by the ``kesbrdf_prior`` plugin
   (:mod:`kesbrdf.render.prior_bsdf`), so each model is scored against the same
   reference render and the same noise floor.
3. Render the scene with the reference as the cloth's BSDF (seed s), then with the
   model (seed s + 1), same camera, lights and spp.  A third render, the reference with
   seed s + 1, gives the *noise floor*: the same metrics between two renders that differ
   only in Monte-Carlo noise.  The model's numbers and the floor's then differ only in
   the BSDF; a model error at the noise floor is not measurable at that spp.
4. Metrics on the cloth pixels (a mask from one primary ray per pixel centre):

   - **FLIP** (NVIDIA ꟻLIP, ``flip_evaluator``, LDR mode at 67 pixels per degree) on the
     displayed sRGB images; the mean over cloth pixels, and the map over the image.
   - **relative RMSE** on linear radiance, ‖M − R‖₂ / ‖R‖₂ over cloth pixels and RGB.

Display: both images are scaled by one exposure chosen on the reference so that its
99.5th-percentile cloth luminance maps to 0.9 (``exposure="auto"``), then sRGB-encoded.
A satin's narrow highlight therefore sits just below white and the body shows as the
dark value it has; the same scale is applied to the model image, so a model that loses
the highlight looks it.

Outputs: one PNG panel (reference | model | FLIP map, one model and map pair per
model, labelled with the numbers) and a JSON file with the numbers and how they were made.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf._atomic import atomic_path, write_text
from kesbrdf.errors import KesbrdfError
from kesbrdf.render import scenes as _scenes
from kesbrdf.render.reference_bsdf import make_reference, reference_bsdf_dict  # noqa: F401 (re-exported)

__all__ = [
    "PROTOCOLS",
    "MODELS",
    "DEFAULT_REFERENCES",
    "default_options",
    "fit_reference_model",
    "fit_spec",
    "model_bsdf_dict",
    "cloth_mask",
    "flip_mean",
    "relative_rmse",
    "auto_exposure",
    "compare_images",
    "compare_render",
    "write_panel",
]

PROTOCOLS = ("paper", "dense")
#: Models a comparison can render besides any registered kind name: ``default`` (the
#: rule of ``kesbrdf fit``, ``kind="auto"``), ``kes`` (the protocol's KES kind: ``kes`` on
#: the paper protocol, ``kes-halfdiff`` on the dense grid), ``fibre-prior`` (prior ×
#: residual) and ``prior-only`` (the same kind fitted with ``residual=False``: the pure prior).
MODELS = ("default", "kes", "fibre-prior", "prior-only")
#: Panel titles by model kind (other kinds show their name).
MODEL_TITLES = {"kes": "KES", "kes-halfdiff": "KES half/diff", "fibre-prior": "prior+residual",
                "prior-only": "prior only"}


def model_names() -> tuple[str, ...]:
    """Every name ``models`` accepts: :data:`MODELS` and the registered kinds."""
    from kesbrdf.models.base import known_fitters

    return MODELS + tuple(k for k in known_fitters() if k not in MODELS)


def model_title(name: str, kind: str) -> str:
    """Panel title of model ``name`` that came out as ``kind``."""
    title = MODEL_TITLES.get("prior-only" if name == "prior-only" else kind, kind)
    return f"default: {title}" if name == "default" else title
#: References compared by default (the CLI's, the satins, one felt).
DEFAULT_REFERENCES = ("satin-ward", "ashikhmin-shirley", "sadeghi-satin", "sadeghi-black-satin", "rgl-felt-white")
#: Displayed value of the reference's 99.5th-percentile cloth luminance (auto exposure).
AUTO_EXPOSURE_TARGET = 0.9
AUTO_EXPOSURE_QUANTILE = 0.995
#: Pixels per degree for FLIP (its default: a 0.7 m viewing distance on a 4K 0.7 m monitor).
FLIP_PPD = 67.0
_REC709 = np.array([0.2126, 0.7152, 0.0722])


#: Panel size and samples of a comparison: 480 × 360 at 64 spp, denoised by OIDN when
#: pyoidn is installed.  Noise floor (FLIP between two seeds of the reference,
#: sadeghi-black-satin on the sphere, measured in one run): 0.054 at 32 spp, 0.044 at 64,
#: 0.034 at 128 without denoising; 0.038 at 16 spp, 0.033 at 32 and 0.028 at 64 with
#: OIDN (docs/rendering.md, "Studio").  Below 0.03 needs 64 spp + OIDN.
PANEL_RESOLUTION = (480, 360)
PANEL_SPP = 64
#: Panels smaller than this are not denoised by default.
DENOISE_MIN_PIXELS = 128 * 96


def default_options(**kw) -> "_scenes.RenderOptions":
    """Render options of a comparison: :data:`PANEL_RESOLUTION`, :data:`PANEL_SPP`,
    OIDN when installed (from :data:`DENOISE_MIN_PIXELS` up), area light, no environment."""
    base = {"spp": PANEL_SPP, "resolution": PANEL_RESOLUTION, "env": "none", "light": "area"}
    base.update(kw)
    if "denoise" not in kw:  # thumbnails (tests) stay raw: OIDN's set-up costs more than it saves there
        w, h = base["resolution"]
        base["denoise"] = _scenes.can_denoise() and int(w) * int(h) >= DENOISE_MIN_PIXELS
    return _scenes.RenderOptions(**base)


def fit_reference_model(ref, protocol: str = "paper", model: str = "default", measurement=None):
    """Measure ``ref`` virtually and fit ``model`` (one of :func:`model_names`) for that protocol
    with the pipeline's fit step (:func:`kesbrdf.pipeline.fit`, spec :func:`fit_spec`).

    ``measurement`` reuses a measurement of ``ref`` with that protocol.  Returns
    (fitted model, n_samples).
    """
    from kesbrdf.measure.gonio import measure

    if protocol not in PROTOCOLS:
        raise KesbrdfError(f"unknown protocol {protocol!r}; expected one of {', '.join(PROTOCOLS)}")
    if model not in model_names():
        raise KesbrdfError(f"unknown model {model!r}; expected one of {', '.join(model_names())}")
    from kesbrdf.pipeline import fit

    m = measurement if measurement is not None else measure(ref, protocol=protocol)
    return fit(m, fit_spec(protocol, model)).model, len(m)


def fit_spec(protocol: str, model: str = "default"):
    """The pipeline's fit spec (:class:`kesbrdf.pipeline.FitSpec`) of a comparison model:
    ``kesbrdf fit``'s rule (``default``), the protocol's KES kind with the log fallback
    (``kes``), the fibre prior with (``fibre-prior``) or without (``prior-only``) its
    residual, or another registered kind with its defaults."""
    from kesbrdf.pipeline import FitSpec

    if model == "default":
        return FitSpec("auto")
    if model in ("fibre-prior", "prior-only"):
        return FitSpec("fibre-prior", {"residual": model == "fibre-prior"})
    if model == "kes":
        return FitSpec("kes" if protocol == "paper" else "kes-halfdiff", {"fallback": "log"})
    return FitSpec(model)


def model_bsdf_dict(model_path, model, opts: "_scenes.RenderOptions") -> dict:
    """The plugin entry rendering ``model`` saved at ``model_path``, any kind
    (:func:`kesbrdf.render.scenes.bsdf_dict`)."""
    return _scenes.bsdf_dict(model_path, opts, model)


def cloth_mask(scene: "mi.Scene", shape_id: str = "cloth") -> np.ndarray:
    """Boolean (H, W): the primary ray through each pixel centre hits the shape ``shape_id``."""
    sensor = scene.sensors()[0]
    w, h = (int(v) for v in sensor.film().size())
    cloth = [s for s in scene.shapes() if s.id() == shape_id]
    if not cloth:
        raise KesbrdfError(f"scene has no shape with id {shape_id!r}")
    idx = dr.arange(mi.UInt32, w * h)
    x = mi.Float(idx % w)
    y = mi.Float(idx // w)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((x + 0.5) / w, (y + 0.5) / h), mi.Point2f(0.5))
    si = scene.ray_intersect(ray)
    return np.array(si.shape == mi.ShapePtr(cloth[0]), bool).reshape(h, w)


def luminance(img: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (..., 3)."""
    return np.asarray(img, float)[..., :3] @ _REC709


def auto_exposure(reference: np.ndarray, mask: np.ndarray) -> float:
    """Exposure in stops putting the reference's bright cloth pixels at the target value."""
    lum = luminance(reference)[mask] if mask.any() else luminance(reference).ravel()
    top = float(np.quantile(lum, AUTO_EXPOSURE_QUANTILE)) if lum.size else 0.0
    return math.log2(AUTO_EXPOSURE_TARGET / top) if top > 0 else 0.0


def relative_rmse(test: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """‖test − reference‖₂ / ‖reference‖₂ over the masked pixels and RGB (linear)."""
    d = (np.asarray(test, float) - np.asarray(reference, float))[mask]
    r = np.asarray(reference, float)[mask]
    denom = float(np.sqrt(np.mean(r * r))) if r.size else 0.0
    return float(np.sqrt(np.mean(d * d))) / denom if denom > 0 else float("nan")


def flip_mean(test_srgb8: np.ndarray, reference_srgb8: np.ndarray, mask: np.ndarray):
    """(mean FLIP over the mask, FLIP value map (H, W), magma map (H, W, 3) uint8)."""
    import flip_evaluator

    ref = np.ascontiguousarray(reference_srgb8, np.float32) / 255.0
    tst = np.ascontiguousarray(test_srgb8, np.float32) / 255.0
    value, _, _ = flip_evaluator.evaluate(ref, tst, "LDR", applyMagma=False, parameters={"ppd": FLIP_PPD})
    value = np.asarray(value, float).reshape(ref.shape[:2])
    magma, _, _ = flip_evaluator.evaluate(ref, tst, "LDR", applyMagma=True, computeMeanError=False,
                                          parameters={"ppd": FLIP_PPD})
    magma8 = (np.clip(np.asarray(magma, float), 0, 1) * 255 + 0.5).astype(np.uint8)
    mean = float(value[mask].mean()) if mask.any() else float(value.mean())
    return mean, value, magma8


def compare_images(reference: np.ndarray, test: np.ndarray, mask: np.ndarray, exposure: float) -> dict:
    """FLIP (displayed images) and relative RMSE (linear) of ``test`` against ``reference``."""
    ref8 = _scenes.to_srgb8(reference, exposure)
    tst8 = _scenes.to_srgb8(test, exposure)
    flip, _, magma = flip_mean(tst8, ref8, mask)
    return {"flip": flip, "rel_rmse": relative_rmse(test, reference, mask), "_magma": magma,
            "_ref8": ref8, "_test8": tst8}


#: The reference's own renders (cloth mask, seed-``opts.seed`` image, seed+1 image or
#: None) by (reference, scene, options, parameters): they do not depend on the protocol,
#: so comparing both protocols renders the reference once, not twice (issue 17).  With
#: fixed seeds a new render differs from the cached one only by the renderer's run-to-run
#: float differences (~1e-4 in FLIP), far below the noise floor.  A few entries of two
#: 480x360 float images each.
_REFERENCE_RENDERS: dict = {}
_REFERENCE_RENDERS_MAX = 4


def _reference_renders(reference: str, scene: str, opts, o2, params, noise_floor: bool):
    """(mask, reference image, second-seed reference image or None), rendered or cached."""
    key = (reference, scene, repr(opts), repr(o2), json.dumps(params, sort_keys=True, default=str))
    got = _REFERENCE_RENDERS.get(key)
    if got is not None and (got[2] is not None or not noise_floor):  # copies: callers own their arrays
        return got[0].copy(), got[1].copy(), got[2].copy() if noise_floor else None
    ref_bsdf = reference_bsdf_dict(reference, two_sided=opts.two_sided, params=params, sampling=opts.sampling)
    ref_scene = _scenes.load_scene(None, scene, opts, cloth_bsdf=ref_bsdf)
    mask = cloth_mask(ref_scene)
    img_ref = _scenes.render_scene(ref_scene, opts)
    del ref_scene
    img_ref2 = None
    if noise_floor:
        img_ref2 = _scenes.render_scene(_scenes.load_scene(None, scene, o2, cloth_bsdf=ref_bsdf), o2)
    if len(_REFERENCE_RENDERS) >= _REFERENCE_RENDERS_MAX:
        _REFERENCE_RENDERS.pop(next(iter(_REFERENCE_RENDERS)))
    _REFERENCE_RENDERS[key] = (mask.copy(), img_ref.copy(), None if img_ref2 is None else img_ref2.copy())
    return mask, img_ref, img_ref2


def compare_render(reference: str, protocol: str = "paper", scene: str = "sphere", opts=None,
                   output=None, params=None, noise_floor: bool = True, models=("default",),
                   given: dict | None = None) -> dict:
    """Render ``scene`` with the reference and with its fitted model(s); compare.

    Parameters
    ----------
    reference : str
        A name of :data:`kesbrdf.render.reference_bsdf.REFERENCE_NAMES`.
    protocol : {"paper", "dense"}
    scene : str
        A scene of :data:`kesbrdf.render.scenes.SCENES` without a drape folder.
    opts : RenderOptions, optional
        Default :func:`default_options`: 480x360, 64 spp + OIDN, the area light alone in a dark
        room (``env="none"``): one small source shows the lobe's shape, where a broad
        environment averages it away (and doubles the noise floor at equal spp).
    output : path, optional
        PNG panel to write; the numbers go next to it as ``<stem>.json``.
    noise_floor : bool
        Also render the reference with another seed (module docstring, step 3).
    models : sequence of :func:`model_names`
        Models fitted to the one measurement and rendered (default: ``kesbrdf fit``'s
        rule alone).
    given : dict, optional
        {name: model} already fitted to a measurement of ``reference`` with ``protocol``
        (``kesbrdf demo`` passes the model it fitted from its camera frames): rendered as
        they are instead of being fitted again.

    Returns
    -------
    dict
        ``flip``, ``rel_rmse`` (the first model vs the reference), ``noise_flip``,
        ``noise_rel_rmse``, ``exposure`` (stops), ``cloth_pixels``, the reference,
        protocol, scene, options, the first model's kind and the sample count;
        ``models``: {name: {"kind", "flip", "rel_rmse"}} for every model; plus the panel
        and JSON paths.
    """
    from kesbrdf.measure.gonio import measure

    if protocol not in PROTOCOLS:
        raise KesbrdfError(f"unknown protocol {protocol!r}; expected one of {', '.join(PROTOCOLS)}")
    models = tuple(models)
    bad = [mo for mo in models if mo not in model_names()] or ([] if models else ["(none)"])
    if bad or len(set(models)) != len(models):
        raise KesbrdfError(f"compare: expected distinct models from {', '.join(model_names())}, "
                           f"got {', '.join(models) or '(none)'}")
    opts = (opts or default_options()).validate()
    ref = make_reference(reference, params)
    m = measure(ref, protocol=protocol)
    given = dict(given or {})
    fitted = {mo: given[mo] if mo in given else fit_reference_model(ref, protocol, mo, m)[0] for mo in models}
    n_samples = len(m)
    # the models and the second reference use the same other seed: the comparisons
    # then differ only in the cloth's BSDF, not in the noise
    o2 = replace(opts, seed=int(opts.seed) + 1)
    images = {}
    with tempfile.TemporaryDirectory(prefix="kesbrdf-compare-") as tmp:
        mask, img_ref, img_ref2 = _reference_renders(reference, scene, opts, o2, params, noise_floor)
        for mo, model in fitted.items():
            model_path = Path(tmp) / f"{mo}.kes.json"
            model.save(model_path)
            mod_scene = _scenes.load_scene(None, scene, o2, cloth_bsdf=model_bsdf_dict(model_path, model, o2))
            images[mo] = _scenes.render_scene(mod_scene, o2)
    exposure = auto_exposure(img_ref, mask) + float(opts.exposure)
    results = {mo: compare_images(img_ref, img, mask, exposure) for mo, img in images.items()}
    first = results[models[0]]
    out = {
        "reference": reference,
        "protocol": protocol,
        "scene": scene,
        "model_kind": fitted[models[0]].kind,
        "samples": n_samples,
        "flip": first["flip"],
        "rel_rmse": first["rel_rmse"],
        "models": {mo: {"kind": fitted[mo].kind, "flip": r["flip"], "rel_rmse": r["rel_rmse"],
                        "fitted": "given" if mo in given else "from a virtual measurement of the reference"}
                   for mo, r in results.items()},
        "exposure": exposure,
        "cloth_pixels": int(mask.sum()),
        "options": opts.to_json(),
        "reference_params": getattr(ref, "params", lambda: {})(),
    }
    if img_ref2 is not None:
        noise = compare_images(img_ref, img_ref2, mask, exposure)
        out["noise_flip"] = noise["flip"]
        out["noise_rel_rmse"] = noise["rel_rmse"]
    out["_images"] = {"reference": img_ref, "model": images[models[0]], "mask": mask,
                      **{f"model:{mo}": img for mo, img in images.items()}}
    if output is not None:
        output = Path(output)
        columns = [(f"{model_title(mo, out['models'][mo]['kind'])} model ({protocol})", results[mo])
                   for mo in models]
        write_panel(output, first["_ref8"], first["_test8"], first["_magma"], out, columns=columns)
        meta = {k: v for k, v in out.items() if not k.startswith("_")}
        json_path = output.with_suffix(".json")
        write_text(json_path, json.dumps(meta, indent=1, default=str) + "\n")
        out["panel"] = str(output)
        out["json"] = str(json_path)
    return out


def write_panel(path, ref8: np.ndarray, model8: np.ndarray, flip8: np.ndarray, numbers: dict,
                columns=None) -> Path:
    """Write reference | model | FLIP map side by side, labelled, as a PNG (atomically).

    ``columns``, a list of (title, :func:`compare_images` result), draws one model and
    FLIP map pair per entry instead of ``model8``/``flip8``.
    """
    from PIL import Image, ImageDraw
    from PIL.PngImagePlugin import PngInfo

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise KesbrdfError(f"compare: expected a panel file ending .png, got {path.name!r}")
    if columns is None:
        kind = "KES" if numbers.get("protocol") == "paper" else "KES half/diff"
        columns = [(f"{kind} model ({numbers.get('protocol')})",
                    {"_test8": model8, "_magma": flip8, "flip": numbers["flip"], "rel_rmse": numbers["rel_rmse"]})]
    h, w = ref8.shape[:2]
    band = 14
    n = 1 + 2 * len(columns)
    panel = Image.new("RGB", (n * w, h + 2 * band), (16, 16, 16))
    images = [ref8] + [img for _, r in columns for img in (r["_test8"], r["_magma"])]
    titles = [f"reference: {numbers.get('reference')}"] + [t for title, _ in columns for t in (title, "FLIP error")]
    for k, img in enumerate(images):
        panel.paste(Image.fromarray(np.ascontiguousarray(img[..., :3])), (k * w, band))
    draw = ImageDraw.Draw(panel)
    for k, t in enumerate(titles):
        draw.text((k * w + 3, 1), t, fill=(230, 230, 230))
    if len(columns) == 1:
        text = f"FLIP {columns[0][1]['flip']:.3f}  relRMSE {columns[0][1]['rel_rmse']:.3f}"
    else:
        text = "   ".join(f"{title.split(' model')[0]}: FLIP {r['flip']:.3f} relRMSE {r['rel_rmse']:.3f}"
                           for title, r in columns)
    if "noise_flip" in numbers:
        text += f"   noise floor: FLIP {numbers['noise_flip']:.3f}  relRMSE {numbers['noise_rel_rmse']:.3f}"
    draw.text((3, h + band + 1), text, fill=(230, 230, 230))
    info = PngInfo()
    info.add_text("kesbrdf", json.dumps({k: v for k, v in numbers.items() if not k.startswith("_")}, default=str))
    with atomic_path(path) as tmp:
        panel.save(tmp, format="PNG", pnginfo=info)
    return path
