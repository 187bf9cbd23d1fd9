r"""Measuring a highlight on a rendered image: how satin-like does it read?

A black satin reads as satin when a near-black body carries a bright, narrow highlight
stretched across the warp floats.  Three numbers on the cloth pixels of a linear render
say how much of that survives (all on Rec. 709 luminance L):

* ``contrast``: peak / median, peak = the :data:`PEAK_QUANTILE` quantile of L (robust
  to single fireflies).  A matte or pink body gives a small ratio; satin a large one.
* ``elongation`` and ``orientation_deg``: the second-moment ellipse of the highlight
  pixels (L ≥ :data:`HIGHLIGHT_FRACTION` × peak), weighted by L: √(λ₁/λ₂) of the pixel
  coordinates' weighted covariance and the angle of its major axis from the image x
  axis (degrees, in (−90°, 90°]).
* ``highlight_area``: the fraction of cloth pixels in the highlight.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["highlight_stats", "PEAK_QUANTILE", "HIGHLIGHT_FRACTION", "orientation_difference_deg"]

#: Quantile of the cloth luminance taken as the highlight's peak.
PEAK_QUANTILE = 0.995
#: Highlight pixels: luminance at least this fraction of the peak.
HIGHLIGHT_FRACTION = 0.5
_REC709 = np.array([0.2126, 0.7152, 0.0722])


def highlight_stats(img: np.ndarray, mask: np.ndarray | None = None) -> dict:
    """Contrast, elongation, orientation and area of the highlight (module docstring).

    Parameters
    ----------
    img : ndarray (H, W, 3)
        Linear RGB.
    mask : ndarray (H, W) of bool, optional
        Cloth pixels (default: all).
    """
    lum = np.asarray(img, float)[..., :3] @ _REC709
    mask = np.ones(lum.shape, bool) if mask is None else np.asarray(mask, bool)
    values = lum[mask]
    if values.size == 0:
        raise ValueError("highlight_stats: expected some cloth pixels, got an empty mask")
    peak = float(np.quantile(values, PEAK_QUANTILE))
    median = float(np.median(values))
    sel = mask & (lum >= HIGHLIGHT_FRACTION * peak)
    ys, xs = np.nonzero(sel)
    w = lum[sel]
    out = {
        "peak": peak,
        "median": median,
        "contrast": peak / median if median > 0 else float("inf"),
        "highlight_area": float(sel.sum()) / float(mask.sum()),
        "highlight_pixels": int(sel.sum()),
    }
    if xs.size >= 3 and w.sum() > 0:
        mx, my = np.average(xs, weights=w), np.average(ys, weights=w)
        cxx = np.average((xs - mx) ** 2, weights=w)
        cyy = np.average((ys - my) ** 2, weights=w)
        cxy = np.average((xs - mx) * (ys - my), weights=w)
        evals, evecs = np.linalg.eigh(np.array([[cxx, cxy], [cxy, cyy]]))
        major = evecs[:, 1]
        angle = math.degrees(math.atan2(-major[1], major[0]))  # image y points down
        angle = (angle + 90.0) % 180.0 - 90.0
        out.update(
            elongation=float(math.sqrt(evals[1] / evals[0])) if evals[0] > 0 else float("inf"),
            orientation_deg=float(angle),
            centroid=(float(mx), float(my)),
        )
    else:
        out.update(elongation=float("nan"), orientation_deg=float("nan"), centroid=(float("nan"), float("nan")))
    return out


def orientation_difference_deg(a: float, b: float) -> float:
    """Smallest angle between two axis orientations (degrees, 0–90)."""
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)
