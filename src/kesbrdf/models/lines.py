"""The in-plane lines of a measurement: one orientation's incidence line, interpolation
along θ_i and over ψ, and the relative noise of a line.

Shared by the kind selection (:mod:`kesbrdf.validate.selection`: the mirror test and the
KES-free baseline) and the σ of kes models (:mod:`kesbrdf.models.kes_sigma`: the data's own
leave-one-orientation-out error), so it lives in the model layer.
"""

from __future__ import annotations

import numpy as np

__all__ = ["line", "on_theta_i", "relative_noise", "orientation_interpolation_predictions"]


def line(m, psi_deg: float):
    """(θ_i°, values, θ_r°, σ or None) of the in-plane rows at ``psi_deg``, sorted by θ_i; or None."""
    psi = np.degrees(np.where(m.is_in_plane, m.psi, np.nan))
    rows = np.abs(psi - psi_deg) < 0.5
    if np.count_nonzero(rows) < 3:
        return None
    ti = np.degrees(m.theta_i[rows])
    sums = ti + np.degrees(m.theta_r[rows])
    if np.ptp(sums) > 0.5 or np.unique(np.round(ti, 6)).size != ti.size:
        # interpolation along θ_i below needs one incidence line θ_i + θ_r = const (the
        # paper's protocol); several lines would mix into a meaningless curve
        from kesbrdf.errors import MeasurementError

        raise MeasurementError(
            f"{m.source or 'measurement'}: psi = {psi_deg:g} deg: expected one incidence line (theta_i + theta_r "
            f"constant, each theta_i once), got theta_i + theta_r from {sums.min():.1f} to {sums.max():.1f} deg "
            f"over {ti.size} rows")
    order = np.argsort(ti)
    sigma = None if m.uncertainty is None else np.asarray(m.uncertainty, float)[rows][order]
    return ti[order], m.values[rows][order], np.degrees(m.theta_r[rows])[order], sigma


def on_theta_i(theta_i, values, at):
    """``values`` (N, C) interpolated per channel at θ_i = ``at``; NaN outside the range."""
    return np.stack([np.interp(at, theta_i, values[:, c], left=np.nan, right=np.nan)
                     for c in range(values.shape[1])], axis=-1)


def relative_noise(line_) -> np.ndarray:
    """σ/|y| of a line: its own uncertainty, else a robust estimate from its roughness.

    Without an uncertainty column, the noise of ln y is estimated from the second
    differences along θ_i: for white noise of σ, Δ²(ln y) has σ√6, and 1.4826 × the
    median |Δ²| is σ√6 robustly.  A sharp highlight makes it larger than the noise
    (the satins: 0.08 with no noise at all), which only makes the mirror test
    (:func:`kesbrdf.validate.selection.mirror_test`) more willing to call the biases alike.
    """
    ti, v, _, sigma = line_
    if sigma is not None:
        return np.abs(sigma) / np.maximum(np.abs(v), 1e-300)
    logv = np.log(np.maximum(v, 1e-12 * np.max(np.abs(v)) + 1e-300))
    d2 = logv[2:] - 2 * logv[1:-1] + logv[:-2]
    return np.full(v.shape, 1.4826 * float(np.median(np.abs(d2))) / np.sqrt(6.0))


def orientation_interpolation_predictions(measurement) -> dict:
    """``{psi_deg: (line, prediction)}``: each measured orientation's in-plane line
    (θ_i°, values, θ_r°, σ or None; one incidence line) and its prediction, at its own
    θ_i, as the mean of the lines at ψ ± 45° (NaN outside their θ_i range); only the
    orientations whose two neighbours were measured."""
    lines = {p: line(measurement, p) for p in (0.0, 45.0, 90.0, 135.0)}
    out = {}
    for p, one in lines.items():
        lo, hi = lines[(p - 45.0) % 180.0], lines[(p + 45.0) % 180.0]
        if one is None or lo is None or hi is None:
            continue
        out[f"{p:g}"] = (one, 0.5 * (on_theta_i(lo[0], lo[1], one[0]) + on_theta_i(hi[0], hi[1], one[0])))
    return out
