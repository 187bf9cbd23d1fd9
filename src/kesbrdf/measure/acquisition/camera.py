r"""A virtual gonioreflectometer that takes pictures.

:func:`simulate_images` photographs a flat fabric sample with any reference BRDF
(a callable ``f(wi, wr) -> (..., C)``) at the geometries of a measurement protocol
(:func:`kesbrdf.measure.gonio.protocol_geometry`), plus white-reference and dark frames, and
writes the frames and a manifest that :func:`kesbrdf.measure.acquisition.ingest.ingest` reads.

Why numpy and not Mitsuba
-------------------------
The rig's geometry is a flat, homogeneous sample under a distant (collimated) light,
seen by a distant (telecentric, or far enough to be) camera.  Every pixel on the
sample then sees the *same* pair (wi, wr), so the noise-free image is one constant
per channel on the sample:

.. math:: r = K\,f_r(\omega_i, \omega_r)\,\cos\theta_i \quad [e^-/s]

with :math:`K = \pi\,r_{white}`, where :math:`r_{white}` is the photoelectron rate of an
ideal white (R = 1, f_r = 1/π) lit at normal incidence.  A path tracer such as Mitsuba
would compute exactly this constant per pixel (the radiance of a flat BRDF sample
under a directional emitter has no spatial variation and no interreflection), at
thousands of times the cost and with Monte-Carlo noise that a real camera does not
have.  Everything that makes real frames differ from that constant is in the sensor
(:class:`kesbrdf.measure.acquisition.sensor.Sensor`: photon and read noise, dark current,
clipping, vignetting, quantisation), which is simulated per pixel.  The frame shows
the sample as a square of side ``size − 2·margin`` pixels on a black mount
(reflectance 0), and the manifest's ROI is that square inset by ``roi_inset`` pixels.
The camera is assumed to be framed so that the sample fills the same pixels at every
θ_r (as the paper's cropped OGM images do); foreshortening is not modelled because it
changes only how many pixels see the sample, not their value.

Exposure
--------
``exposure="auto"`` picks, for each frame, the longest time of a doubling ladder
(2⁻¹³ … 2⁵ s) whose expected brightest pixel stays below ``auto_target`` of the full
well, as a careful operator would; a fixed number of seconds for every sample frame
lets highlights clip.  Dark frames are taken at every exposure used.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from kesbrdf.measure.acquisition.images import write_image
from kesbrdf.measure.acquisition.manifest import write_manifest
from kesbrdf.measure.acquisition.sensor import Sensor
from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.geometry import in_plane_directions
from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG

__all__ = ["simulate_images", "EXPOSURE_LADDER_S", "WHITE_LAYOUTS", "FILE_FORMATS"]

#: Exposure times the auto-exposure chooses from, s (doubling steps, 1/8192 s … 32 s).
EXPOSURE_LADDER_S = 2.0 ** np.arange(-13, 6)
#: Where white-reference frames are taken: at every sample geometry, at every fourth
#: (the rest use the cosine model of the reference in ingest), or nowhere.
WHITE_LAYOUTS = ("all", "sparse", "none")
FILE_FORMATS = {"tiff": ".tif", "png": ".png", "exr": ".exr"}


def _auto_exposure(peak_rate, sensor: Sensor, target: float) -> float:
    """Longest ladder time whose expected brightest pixel is below target × full well."""
    budget = target * sensor.full_well_e
    electrons = (peak_rate + sensor.dark_current_e_per_s) * EXPOSURE_LADDER_S
    ok = np.nonzero(electrons <= budget)[0]
    return float(EXPOSURE_LADDER_S[ok[-1]] if ok.size else EXPOSURE_LADDER_S[0])


def _tag(x: float) -> str:
    return f"{x:g}".replace(".", "p")


def simulate_images(
    brdf,
    outdir,
    protocol: str = "paper",
    step_deg: float | None = None,
    *,
    orientations_deg=PAPER_ORIENTATIONS_DEG,
    size: int = 32,
    margin: int = 4,
    roi_inset: int = 2,
    sensor: Sensor | None = None,
    exposure="auto",
    white_exposure="auto",
    auto_target: float = 0.5,
    white_rate_e_per_s: float = 2.0e5,
    white_reflectance: float = 0.99,
    whites: str = "all",
    n_dark: int = 1,
    file_format: str = "tiff",
    seed: int | None = 0,
    sample: str | None = None,
    progress=None,
) -> Path:
    """Photograph ``brdf`` in a protocol and write frames plus ``manifest.csv``.

    Parameters
    ----------
    brdf : callable
        ``f(wi, wr) -> (..., C)`` in 1/sr with C = 1 or 3 (attribute ``channels``
        optional).
    outdir : path
        Folder for the frames and ``manifest.csv`` (created).
    protocol, step_deg, orientations_deg
        As :func:`kesbrdf.measure.gonio.protocol_geometry` (``"paper"``: 4 × 29 frames).
    size, margin, roi_inset : int
        Frame side, mount border and ROI inset, pixels.
    sensor : Sensor, optional
        Default ``Sensor()`` (16-bit linear, no vignetting).
    exposure, white_exposure : "auto" or float
        Exposure of sample / white frames, s (module docstring).
    auto_target : float
        Fraction of the full well the auto-exposure aims the brightest pixel at.
    white_rate_e_per_s : float
        Photoelectron rate of an ideal white at normal incidence (sets K).
    white_reflectance : float
        Reflectance factor R of the white reference (f_r = R/π).
    whites : {"all", "sparse", "none"}
        Where white frames are taken (:data:`WHITE_LAYOUTS`).
    n_dark : int
        Dark frames per exposure time.
    file_format : {"tiff", "png", "exr"}
        16-bit colour needs TIFF or EXR (see :mod:`kesbrdf.measure.acquisition.images`).
    seed : int or None
        Seed of the noise; a fixed seed regenerates identical frames.
    sample : str, optional
        Sample name for the manifest header.
    progress : callable, optional
        ``progress(done, total)`` after every frame written.

    Returns
    -------
    Path
        The manifest path.
    """
    from kesbrdf.measure.gonio import protocol_geometry

    sensor = sensor or Sensor()
    validate_choice("whites", whites, WHITE_LAYOUTS)
    validate_choice("file_format", file_format, FILE_FORMATS)
    room = isinstance(size, int) and size >= 4 and margin >= 0 and roi_inset >= 0
    if not (room and size - 2 * (margin + roi_inset) >= 1):
        raise KesbrdfError(
            f"expected size >= 4 with room for the ROI, got size={size}, margin={margin}, roi_inset={roi_inset}"
        )
    if not (0 < white_reflectance <= 1):
        raise KesbrdfError(f"white_reflectance: expected a reflectance factor in (0, 1], got {white_reflectance!r}")
    for name, value in (("exposure", exposure), ("white_exposure", white_exposure)):
        if value != "auto" and not (isinstance(value, (int, float)) and value > 0):
            raise KesbrdfError(f"{name}: expected 'auto' or seconds > 0, got {value!r}")
    suffix = FILE_FORMATS[file_format]
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)

    # Noise-free scene: one f_r per geometry and channel (module docstring).
    psi, theta_i, theta_r = protocol_geometry(protocol, step_deg, orientations_deg)
    wi, wr = in_plane_directions(psi, theta_i, theta_r)
    f_r = np.asarray(brdf(wi, wr), float)
    if f_r.ndim == 1:
        f_r = f_r[:, None]
    n_channels = f_r.shape[-1]
    if n_channels == 3 and suffix == ".png" and sensor.bit_depth == 16:
        raise KesbrdfError("16-bit colour frames cannot be PNG (Pillow reads them as 8 bits); use file_format='tiff'")
    if n_channels not in (1, 3):
        raise KesbrdfError(f"expected a BRDF with 1 or 3 channels for images, got {n_channels}")
    if not np.all(np.isfinite(f_r)):
        raise KesbrdfError("the BRDF returned NaN or infinite values at the protocol's geometries")
    K = math.pi * white_rate_e_per_s
    sample_rate = K * f_r * np.cos(theta_i)[:, None]  # (N, C) e-/s on the sample

    mask = np.zeros((size, size, 1))
    mask[margin : size - margin, margin : size - margin] = 1.0
    lo, hi = margin + roi_inset, size - margin - roi_inset
    roi = (lo, lo, hi, hi)

    def exposure_for(rate, setting) -> float:
        return _auto_exposure(float(np.max(rate)), sensor, auto_target) if setting == "auto" else float(setting)

    # Plan every frame first (exposures decide which darks are needed).
    plan: list[dict] = []
    ti_deg, tr_deg, psi_deg = (np.round(np.degrees(a), 9) for a in (theta_i, theta_r, psi))
    geometries = sorted({(a, b) for a, b in zip(ti_deg, tr_deg)}, key=lambda g: (-g[0], g[1]))
    if whites == "all":
        white_geometries = geometries
    elif whites == "sparse":
        white_geometries = geometries[::4] + ([geometries[-1]] if (len(geometries) - 1) % 4 else [])
    else:
        white_geometries = []
    white_value = white_reflectance / math.pi
    for ti, tr in white_geometries:
        rate = np.full(n_channels, K * white_value * math.cos(math.radians(ti)))
        t = exposure_for(rate, white_exposure)
        plan.append(
            dict(
                file=f"white_i{_tag(ti)}_r{_tag(tr)}{suffix}",
                kind="white",
                theta_i_deg=ti,
                theta_r_deg=tr,
                exposure_s=t,
                roi=roi,
                rate=rate,
            )
        )
    for k in range(len(psi)):
        t = exposure_for(sample_rate[k], exposure)
        plan.append(
            dict(
                file=f"sample_p{_tag(psi_deg[k])}_i{_tag(ti_deg[k])}_r{_tag(tr_deg[k])}{suffix}",
                kind="sample",
                psi_deg=float(psi_deg[k]),
                theta_i_deg=float(ti_deg[k]),
                theta_r_deg=float(tr_deg[k]),
                exposure_s=t,
                roi=roi,
                rate=sample_rate[k],
            )
        )
    exposures = sorted({p["exposure_s"] for p in plan})
    darks = [
        dict(file=f"dark_t{_tag(t)}_{j}{suffix}", kind="dark", exposure_s=t, rate=np.zeros(n_channels))
        for t in exposures
        for j in range(n_dark)
    ]
    plan = darks + plan

    total = len(plan)
    for done, frame in enumerate(plan, start=1):
        rate_map = mask * frame["rate"][None, None, :]
        codes = sensor.expose(rate_map, frame["exposure_s"], rng)
        if suffix == ".exr":
            codes = codes.astype(np.float32) / sensor.max_code
        write_image(outdir / frame["file"], codes)
        if progress is not None:
            progress(done, total)

    params = brdf.params() if hasattr(brdf, "params") else {"reference": getattr(brdf, "name", type(brdf).__name__)}
    generator = {
        "brdf": params,
        "protocol": protocol,
        "step_deg": step_deg,
        "orientations_deg": [float(o) for o in orientations_deg],
        "sensor": sensor.params(),
        "exposure": exposure,
        "white_exposure": white_exposure,
        "auto_target": auto_target,
        "white_rate_e_per_s": white_rate_e_per_s,
        "whites": whites,
        "size": size,
        "margin": margin,
        "roi_inset": roi_inset,
        "seed": seed,
    }
    header = {
        "sample": sample or f"simulated {params.get('reference', getattr(brdf, 'name', 'reference'))}",
        "instrument": "kesbrdf virtual gonioreflectometer camera (numpy, distant light and camera)",
        "white_reflectance": repr(float(white_reflectance)),
        "response": sensor.response,
        "simulated": "true",
        "generator": json.dumps(generator, sort_keys=True, default=str),
    }
    if suffix == ".exr":
        header["saturation_level"] = "1.0"
    rows = [{k: v for k, v in p.items() if k != "rate"} for p in plan]
    return write_manifest(outdir / "manifest.csv", header, rows)
