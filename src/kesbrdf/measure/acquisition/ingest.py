r"""From gonioreflectometer photographs to calibrated BRDF values (``kesbrdf ingest``).

For every ``sample`` frame of a manifest (:mod:`kesbrdf.measure.acquisition.manifest`):

1. **Read** the frame (8/16-bit PNG/TIFF, OpenEXR: :mod:`kesbrdf.measure.acquisition.images`)
   and check that it has the size and bit depth of every other frame.
2. **Linearise** it (manifest ``response``) and **subtract the dark frame** of the same
   exposure, pixel by pixel (the mean of all dark frames at that exposure).
3. **Average over the ROI** with a robust statistic per channel: the mean of the pixels
   within ``CLIP_SIGMA`` robust standard deviations (1.4826 × MAD, floored at one
   code step) of the median.
   Unlike the plain median it is not quantised to whole DN (the median of integer
   codes is biased by up to half a DN, which matters for dim 8-bit frames), and like it
   it ignores hot pixels, dust and specks.  Its uncertainty is the standard deviation of
   the kept pixels divided by √n: the pixel spread (photon, read and dark noise, and
   any texture or vignetting inside the ROI) over the number of pixels.
4. **Normalise by exposure** (signal per second) and **calibrate** against the white
   reference, a Lambertian reflector of known reflectance factor R (BRDF R/π):

   .. math::
       f_r = \frac{(S - D_S)/t_S}{(W - D_W)/t_W}\cdot\frac{R}{\pi}

   with the white frame W taken at the same (θ_i, θ_r); the light's irradiance, the
   cosine of incidence, the camera's throughput and gain, and vignetting common to
   both frames all cancel.  **Cosine model of the white**: where no white frame was
   taken at a sample's geometry, the white's signal at fixed exposure is modelled as
   proportional to cos θ_i (an ideal Lambertian: its radiance is (R/π)·E·cos θ_i,
   independent of θ_r), scaled from the white frame(s) nearest in θ_i (then θ_r):
   W(θ_i) = W(θ_i')·cos θ_i / cos θ_i'.  This assumes a stable lamp and an ideal
   Lambertian reference; the summary names the white frame used.
5. **Uncertainty** of f_r by first-order propagation of both ROI uncertainties (the
   reference's R and the cosine model are taken as exact).  Provenance: the file name
   and the SHA-256 of its bytes go into the measurement's ``file`` and
   ``file_sha256`` columns, the outcome into ``flag``.

Problems found
--------------
Each problem is reported as ``manifest:line: file: message``.  Ingest checks every
frame and then raises one :class:`IngestError` naming the first problem and counting
the rest; its ``summary`` lists every frame with its status, so the CLI can show them
all.  Nothing is returned (and the CLI writes nothing) when any frame is rejected.

* frame file missing; image unreadable; size or bit depth unlike the first frame;
* ROI outside the image;
* no dark frame at a frame's exposure; no white frame in the manifest at all;
* clipped (saturated) pixels in the ROI of a sample: ``saturation="reject"`` rejects
  the frame; ``saturation="lower_bound"`` keeps the value with ``flag=lower_bound``
  (clipping can only lower the signal).  A clipped white frame is always rejected
  (it would bias every sample that uses it upward);
* a value negative after dark subtraction by more than ``NEGATIVE_SIGMA`` standard
  uncertainties (a dark frame that does not match): rejected.  A negative value
  within the noise is kept with ``flag=flagged`` (it is consistent with zero).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from kesbrdf.measure.acquisition.images import Frame, linearize, read_image, sha256_file
from kesbrdf.measure.acquisition.manifest import Manifest, ManifestRow, read_manifest
from kesbrdf.errors import KesbrdfError, MeasurementError, where, validate_choice

__all__ = [
    "ingest",
    "IngestResult",
    "IngestError",
    "SummaryRow",
    "robust_mean",
    "SATURATION_MODES",
    "CLIP_SIGMA",
    "NEGATIVE_SIGMA",
]

SATURATION_MODES = ("reject", "lower_bound")
#: Pixels farther than this many robust standard deviations from the ROI median are
#: left out of the mean (4σ keeps 99.994 % of Gaussian noise: a negligible bias).
CLIP_SIGMA = 4.0
#: MAD → standard deviation for Gaussian data.
MAD_TO_SIGMA = 1.4826
#: Quantised frames with noise below a few codes have a MAD of 0 or 1 code, and a
#: window of 4 × 1.4826 × MAD would then cut off genuine noise (biasing the spread
#: low).  So the robust σ is floored at one code step at the median (the smallest
#: non-zero distance from the median among the 90 % of pixels closest to it, in linear
#: units), and never below SIGMA_FLOOR_DN.
SIGMA_FLOOR_DN = math.sqrt(1.0 / 12.0)
#: A dark-subtracted ROI mean below −NEGATIVE_SIGMA × its uncertainty is rejected.
NEGATIVE_SIGMA = 3.0
#: A white frame serves a sample when both θ_i and θ_r agree within this (degrees).
SAME_WHITE_DEG = 0.05

STATUSES = ("used", "flagged", "rejected", "unused")


class IngestError(MeasurementError):
    """Frames of a manifest cannot be turned into a measurement.

    ``summary`` holds every frame's :class:`SummaryRow` (the rejected ones with reasons).
    """

    def __init__(self, message: str, summary=None):
        super().__init__(message)
        self.summary = list(summary or [])


@dataclass
class SummaryRow:
    """What ingest did with one manifest row."""

    line: int
    file: str
    kind: str
    status: str  # used | flagged | rejected | unused
    detail: str = ""


@dataclass
class IngestResult:
    """The measurement made from a manifest and a per-frame summary."""

    measurement: object
    summary: list = field(default_factory=list)
    manifest: Manifest | None = None

    def counts(self) -> dict:
        """Number of frames per status."""
        return {s: sum(r.status == s for r in self.summary) for s in STATUSES}


def robust_mean(pixels) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clipped mean of ROI pixels per channel and its standard uncertainty.

    Parameters
    ----------
    pixels : array_like, shape (n, C)
        Dark-subtracted linear pixel values of one ROI.

    Returns
    -------
    centre, uncertainty : ndarray (C,)
        Mean of the pixels within ``CLIP_SIGMA`` robust σ of the median, and the
        standard deviation of those pixels over √n_kept.
    n_kept : ndarray (C,) of int

    >>> x = np.concatenate([np.full(99, 10.0), [1e6]])[:, None]
    >>> [float(v[0]) for v in robust_mean(x)]
    [10.0, 0.0, 99.0]
    """
    x = np.asarray(pixels, float)
    median = np.median(x, axis=0)
    distance = np.abs(x - median)
    # one code step: the smallest non-zero distance among the 90 % closest pixels (so
    # that a few hot pixels cannot pose as the step)
    q90 = np.quantile(distance, 0.9, axis=0)
    code_step = np.min(np.where((distance > 0) & (distance <= q90), distance, np.inf), axis=0)
    code_step = np.where(np.isfinite(code_step), code_step, 0.0)
    sigma = np.maximum(np.maximum(MAD_TO_SIGMA * np.median(distance, axis=0), code_step), SIGMA_FLOOR_DN)
    keep = distance <= CLIP_SIGMA * sigma
    n_kept = keep.sum(axis=0)
    kept = np.where(keep, x, np.nan)
    centre = np.nanmean(kept, axis=0)
    spread = np.nanstd(kept, axis=0, ddof=1) if x.shape[0] > 1 else np.zeros(x.shape[1])
    return centre, np.nan_to_num(spread) / np.sqrt(n_kept), n_kept


def _exposure_key(t: float) -> float:
    return float(f"{t:.9g}")


@dataclass
class _Signal:
    rate: np.ndarray  # (C,) dark-subtracted signal per second, DN/s
    unc: np.ndarray  # (C,)
    n_saturated: int
    n_pixels: int
    level: float | None
    row: ManifestRow


def ingest(manifest_path, saturation: str = "reject", progress=None) -> IngestResult:
    """Turn a manifest of frames into calibrated BRDF values (module docstring).

    Parameters
    ----------
    manifest_path : path
        The manifest CSV.
    saturation : {"reject", "lower_bound"}
        What to do with a sample frame whose ROI has clipped pixels.
    progress : callable, optional
        ``progress(done, total, file)`` after each frame.

    Returns
    -------
    IngestResult
        ``.measurement`` (:class:`kesbrdf.measure.measurement.Measurement`, f_r in 1/sr with
        uncertainty and provenance) and ``.summary`` (one row per manifest row).

    Raises
    ------
    FormatError
        Malformed manifest.
    IngestError
        Any rejected frame, missing dark or white frames (module docstring).
    """
    from kesbrdf.measure.measurement import Measurement

    validate_choice("saturation", saturation, SATURATION_MODES)
    manifest = read_manifest(manifest_path)
    mpath = manifest.path
    summary = {row.line: SummaryRow(row.line, row.file, row.kind, "unused") for row in manifest.rows}
    problems: list[str] = []

    def reject(row: ManifestRow, message: str) -> None:
        summary[row.line].status = "rejected"
        summary[row.line].detail = message
        problems.append(f"{where(mpath, row.line)}{row.file}: {message}")

    def fail() -> None:
        first = problems[0]
        more = len(problems) - 1
        suffix = f" ({more} more problem{'s' if more > 1 else ''} in other frames)" if more else ""
        raise IngestError(first + suffix, [summary[k] for k in sorted(summary)])

    # 1. Every file must exist.
    for row in manifest.rows:
        if not row.path.is_file():
            reject(row, f"file not found ({row.path})")
    if problems:
        fail()
    darks, whites, samples = (manifest.of_kind(k) for k in ("dark", "white", "sample"))
    if not samples:
        raise IngestError(f"{where(mpath)}expected at least one sample frame, got none")
    if not darks:
        raise IngestError(f"{where(mpath)}missing dark frames: expected dark rows (kind=dark) at every exposure used, got none")
    if not whites:
        raise IngestError(
            f"{where(mpath)}missing white frames: expected at least one white-reference row (kind=white), got none"
        )

    total = len(manifest.rows)
    done = 0

    def tick(row: ManifestRow) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, row.file)

    # 2. Read frames, checking size and bit depth against the first one.
    reference: list[tuple[Frame, ManifestRow]] = []

    def load(row: ManifestRow) -> Frame | None:
        try:
            frame = read_image(row.path)
        except KesbrdfError as exc:
            reject(row, str(exc).removeprefix(where(row.path)))
            return None
        if not reference:
            reference.append((frame, row))
        ref, ref_row = reference[0]
        if frame.shape != ref.shape or frame.dtype != ref.dtype:
            reject(row, f"image is {frame.description}, expected {ref.description} as {ref_row.file} (line {ref_row.line})")
            return None
        if row.roi is not None:
            x0, y0, x1, y1 = row.roi
            h, w = frame.shape[:2]
            if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
                reject(row, f"ROI {x0},{y0},{x1},{y1} falls outside the {w}x{h} image")
                return None
        return frame

    response = manifest.response

    # Master darks: per-pixel mean per exposure, kept only over the box that holds
    # every ROI (a full frame when some sample or white row has no ROI), so that large
    # camera frames with small ROIs do not fill the memory.
    rois = [r.roi for r in whites + samples]
    box = None
    if all(roi is not None for roi in rois):
        box = (
            max(0, min(r[0] for r in rois)),
            max(0, min(r[1] for r in rois)),
            max(r[2] for r in rois),
            max(r[3] for r in rois),
        )

    def crop(pixels: np.ndarray, roi) -> np.ndarray:
        return pixels if roi is None else pixels[roi[1] : roi[3], roi[0] : roi[2]]

    dark_sum: dict[float, list] = {}
    for row in darks:
        frame = load(row)
        tick(row)
        if frame is None:
            continue
        entry = dark_sum.setdefault(_exposure_key(row.exposure_s), [0.0, 0])
        entry[0] = entry[0] + linearize(frame, response, crop(frame.pixels, box))
        entry[1] += 1
        summary[row.line].status = "used"
    master_dark = {t: total / n for t, (total, n) in dark_sum.items()}
    dark_times = ", ".join(f"{t:g}" for t in sorted(master_dark)) or "none usable"

    def roi_in_box(roi):
        """A frame's ROI in the coordinates of the cropped master dark."""
        if roi is None or box is None:
            return roi
        return (roi[0] - box[0], roi[1] - box[1], roi[2] - box[0], roi[3] - box[1])

    def measure(row: ManifestRow) -> _Signal | None:
        frame = load(row)
        if frame is None:
            return None
        dark = master_dark.get(_exposure_key(row.exposure_s))
        if dark is None:
            reject(row, f"missing dark frame: no dark frame at exposure_s={row.exposure_s:g} (darks at: {dark_times} s)")
            return None
        raw = crop(frame.pixels, row.roi)
        level = manifest.saturation_level or frame.max_code
        clipped = ~np.isfinite(raw)
        if level is not None:
            clipped |= raw >= level
        n_saturated = int(np.any(clipped, axis=-1).sum())
        signal = linearize(frame, response, raw) - crop(dark, roi_in_box(row.roi))
        centre, unc, _ = robust_mean(signal.reshape(-1, signal.shape[-1]))
        n_pixels = raw.shape[0] * raw.shape[1]
        return _Signal(centre / row.exposure_s, unc / row.exposure_s, n_saturated, n_pixels, level, row)

    def saturation_text(s: _Signal) -> str:
        at = "non-finite" if s.level is None else f"at or above code {s.level:g}"
        return f"{s.n_saturated} of {s.n_pixels} ROI pixels clipped ({at})"

    # 3. White frames.
    white_signals: list[_Signal] = []
    for row in whites:
        s = measure(row)
        tick(row)
        if s is None:
            continue
        if s.n_saturated:
            reject(row, f"white reference clipped: {saturation_text(s)}; shorten its exposure")
            continue
        if np.any(s.rate <= NEGATIVE_SIGMA * s.unc):
            reject(row, "white reference signal is not above the noise after dark subtraction; lengthen its exposure")
            continue
        white_signals.append(s)
    white_ti = np.array([s.row.theta_i_deg for s in white_signals])
    white_tr = np.array([s.row.theta_r_deg for s in white_signals])

    def white_for(row: ManifestRow):
        """(rate, unc, detail) of the white at this sample's geometry (module docstring)."""
        if not white_signals:
            return None
        same = (np.abs(white_ti - row.theta_i_deg) <= SAME_WHITE_DEG) & (np.abs(white_tr - row.theta_r_deg) <= SAME_WHITE_DEG)
        if np.any(same):
            chosen = [white_signals[k] for k in np.nonzero(same)[0]]
            scale = np.ones(len(chosen))
            how = "white at same geometry"
        else:
            d_i = np.abs(white_ti - row.theta_i_deg)
            nearest_i = d_i <= d_i.min() + SAME_WHITE_DEG
            d_r = np.where(nearest_i, np.abs(white_tr - row.theta_r_deg), np.inf)
            pick = np.nonzero(nearest_i & (d_r <= d_r.min() + SAME_WHITE_DEG))[0]
            chosen = [white_signals[k] for k in pick]
            scale = np.array([math.cos(math.radians(row.theta_i_deg)) / math.cos(math.radians(s.row.theta_i_deg)) for s in chosen])
            how = "cosine model of the white"
        rates = np.array([s.rate for s in chosen]) * scale[:, None]
        uncs = np.array([s.unc for s in chosen]) * scale[:, None]
        names = ", ".join(s.row.file for s in chosen)
        return rates.mean(axis=0), np.sqrt((uncs**2).sum(axis=0)) / len(chosen), f"{how} ({names})", chosen

    # 4. Sample frames.
    R = manifest.white_reflectance
    kept: list[tuple[ManifestRow, np.ndarray, np.ndarray, str]] = []
    for row in samples:
        s = measure(row)
        tick(row)
        if s is None:
            continue
        white = white_for(row)
        if white is None:
            reject(row, "missing white frames: every white-reference frame was rejected")
            continue
        w_rate, w_unc, white_detail, white_used = white
        flag, notes = "ok", []
        if s.n_saturated:
            if saturation == "reject":
                reject(row, f"{saturation_text(s)}; shorten the exposure, or keep it as a lower bound (--saturation lower-bound)")
                continue
            flag = "lower_bound"
            notes.append(f"lower bound: {saturation_text(s)}")
        if np.any(s.rate < -NEGATIVE_SIGMA * s.unc):
            worst = int(np.argmin(s.rate / np.maximum(s.unc, 1e-300)))
            reject(
                row,
                f"value negative after dark subtraction: {s.rate[worst] * row.exposure_s:.4g} ± "
                f"{s.unc[worst] * row.exposure_s:.2g} DN in channel {worst}; does the dark frame match?",
            )
            continue
        if np.any(s.rate < 0):
            if flag == "ok":
                flag = "flagged"
            notes.append("negative after dark subtraction, within the noise (consistent with zero)")
        value = s.rate / w_rate * R / math.pi
        unc = R / math.pi * np.sqrt((s.unc / w_rate) ** 2 + (s.rate * w_unc / w_rate**2) ** 2)
        summary[row.line].status = "used" if flag == "ok" else "flagged"
        summary[row.line].detail = "; ".join(notes + [white_detail])
        kept.append((row, value, unc, flag))
        for ws in white_used:
            summary[ws.row.line].status = "used"
    if problems:
        fail()

    # 5. The measurement.
    n_channels = reference[0][0].shape[-1]
    channels = _channel_names(manifest, n_channels)
    rows = [k[0] for k in kept]
    theta_i = np.radians([r.theta_i_deg for r in rows])
    theta_r = np.radians([r.theta_r_deg for r in rows])
    psi_deg = np.array([np.nan if r.is_general else r.psi_deg for r in rows])
    phi_i = np.radians([r.phi_i_deg if r.is_general else r.psi_deg + 180.0 for r in rows]) % (2 * np.pi)
    phi_r = np.radians([r.phi_r_deg if r.is_general else r.psi_deg for r in rows]) % (2 * np.pi)
    header = manifest.header
    metadata = {
        "sample": header.get("sample", mpath.stem),
        "instrument": header.get("instrument", "image-based gonioreflectometer"),
        "quantity": "brdf",
    }
    for key in ("simulated", "generator"):
        if key in header:
            metadata[key] = header[key]
    metadata["acquisition"] = json.dumps(
        {
            "manifest": mpath.name,
            "manifest_sha256": sha256_file(mpath),
            "white_reflectance": R,
            "response": response,
            "saturation": saturation,
            "statistic": f"mean within {CLIP_SIGMA:g} robust sigma of the ROI median",
        },
        sort_keys=True,
    )
    measurement = Measurement(
        theta_i=theta_i,
        phi_i=phi_i,
        theta_r=theta_r,
        phi_r=phi_r,
        values=np.array([k[1] for k in kept]),
        channels=channels,
        uncertainty=np.array([k[2] for k in kept]),
        psi=np.radians(psi_deg),
        metadata=metadata,
        provenance={
            "file": [r.file for r in rows],
            "file_sha256": [sha256_file(r.path) for r in rows],
            "flag": [k[3] for k in kept],
        },
        notes=[f"{r.file}: {summary[r.line].detail}" for r in rows if summary[r.line].status == "flagged"],
    )
    return IngestResult(measurement=measurement, summary=[summary[k] for k in sorted(summary)], manifest=manifest)


def _channel_names(manifest: Manifest, n_channels: int) -> tuple[str, ...]:
    names = manifest.header.get("channels")
    if names:
        parsed = tuple(n.strip() for n in str(names).split(",") if n.strip())
        if len(parsed) != n_channels:
            raise IngestError(
                f"{where(manifest.path)}channels header: expected {n_channels} names for the frames' channels, got {len(parsed)}"
            )
        return parsed
    return ("value",) if n_channels == 1 else ("R", "G", "B")
