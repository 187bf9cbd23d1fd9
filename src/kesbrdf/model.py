r"""The anisotropic reflection model: the table ρ(φ, γ) (paper STEP 3, DESIGN §4).

:func:`fit` turns in-plane measurements at ψ = 0, π/4, π/2 (and 3π/4) into a
table of the lobe quantity

.. math:: q(\phi, \gamma) = (f_r - c)\,\sqrt{\cos\theta_i\cos\theta_r}

(paper eq. 3's normalisation) over the whole circle of deviation azimuths
φ ∈ [0, 2π) and deviations γ ≥ 0, plus a Lambertian body term c (DESIGN §4).
The table *is* the model: every consumer (numpy BRDF, Mitsuba plugin, browser
viewer) evaluates it by the same bilinear lookup (``docs/formats.md``).

How the table is filled
-----------------------
1. Signed γ = θ_r − θ_i of each in-plane sample at orientation ψ becomes a
   half-sample at deviation azimuth ψ (γ > 0) or ψ + π (γ < 0) with |γ|; at γ = 0
   both halves get the same sample (the plane of incidence, DESIGN §4).
2. Body: ``body="auto"`` takes c = max(0, min f_r) per channel over the in-plane
   samples (the darkest reading is an upper bound of the diffuse floor; noise makes
   it a slight underestimate, which only moves energy to the lobe); ``"none"`` is c = 0
   (the paper's pure lobe); a number sets c.
3. Noise floor: q is floored at ``noise_floor`` (default: 1e-4 × the channel's peak
   q, a 14-bit dynamic range) so that K = 1/q stays finite; every floored
   half-sample is recorded in ``diagnostics["floored"]``.
4. Each of the eight half-sample curves is resampled onto a uniform γ grid
   (linear in q; the grid contains every measured |γ| when they are uniformly
   spaced, so the measured values are kept exactly).
5. For every γ of the grid, K = 1/q is interpolated over φ by :mod:`kesbrdf.kes`.
   Where K(φ) ≤ 0 somewhere (the hazard of DESIGN §3), ``fallback="error"`` raises
   :class:`~kesbrdf.errors.KESError`; ``fallback="log"`` interpolates log q instead at
   that γ and records it in ``diagnostics["fallback_gamma_deg"]``.

Baselines (``interpolation="nearest"`` or ``"linear"``) fill the same table with the
nearest measured half-sample or linear interpolation over φ, so they are evaluated
with the same BRDF machinery and compared on equal terms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from kesbrdf import kes
from kesbrdf._version import __version__
from kesbrdf.errors import KESError, MeasurementError
from kesbrdf.measurement import Measurement

__all__ = ["Model", "fit", "load", "INTERPOLATIONS", "FALLBACKS"]

INTERPOLATIONS = ("kes", "nearest", "linear")
FALLBACKS = ("error", "log")

#: Orientation match tolerance when recognising ψ = 0/45/90/135° in a file.
ORIENTATION_TOL = math.radians(0.5)
#: Default noise floor relative to each channel's peak q.
RELATIVE_NOISE_FLOOR = 1e-4
#: Default φ resolution of the table (1°: measured azimuths k·45° fall on the grid).
DEFAULT_N_PHI = 360
#: Finest default γ step of the table.
MAX_GAMMA_STEP = math.radians(1.0)


@dataclass
class Model:
    """A fitted extended-KES model (see module docstring and docs/formats.md)."""

    channels: tuple[str, ...]
    phi_grid: np.ndarray
    gamma_grid: np.ndarray
    table: np.ndarray
    body: np.ndarray
    gamma_nodes: np.ndarray
    q_nodes: np.ndarray
    kind: str = "kes"
    parameters: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    input_info: dict = field(default_factory=dict)
    kesbrdf_version: str = __version__

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def gamma_max(self) -> float:
        return float(self.gamma_grid[-1])

    @property
    def orientations(self) -> int:
        return int(self.parameters.get("orientations", 4))

    def save(self, path):
        """Write the model file atomically (JSON + base64 arrays, no pickle)."""
        from kesbrdf.io.model_file import save_model

        return save_model(path, self)


def load(path) -> Model:
    """Read a model file written by :meth:`Model.save`."""
    from kesbrdf.io.model_file import load_model

    return load_model(path)


# ---------------------------------------------------------------------------------
def _select_orientations(m: Measurement, orientations):
    present = m.orientations()
    if present.size == 0:
        raise MeasurementError(
            f"{m.source or 'measurement'}: KES needs in-plane samples (psi_deg column) at "
            "psi = 0, 45, 90 (and 135) deg; got none"
        )
    wanted = np.radians([0.0, 45.0, 90.0, 135.0])
    found = [bool(np.any(np.abs(present - w) < ORIENTATION_TOL)) for w in wanted]
    missing3 = [d for d, ok in zip((0, 45, 90), found[:3]) if not ok]
    got = ", ".join(f"{x:g}" for x in np.degrees(present))
    if missing3:
        raise MeasurementError(
            f"{m.source or 'measurement'}: KES needs orientations psi = 0, 45, 90 deg; "
            f"missing {', '.join(map(str, missing3))} (got {got})"
        )
    if orientations is None:
        orientations = 4 if found[3] else 3
    if orientations not in (3, 4):
        raise KESError(f"expected orientations 3 or 4, got {orientations!r}")
    if orientations == 4 and not found[3]:
        raise MeasurementError(
            f"{m.source or 'measurement'}: orientations=4 needs psi = 135 deg; got {got}"
        )
    return orientations


def _incidence_line(m: Measurement, rows: np.ndarray) -> float:
    """The θ_i + θ_r line (radians) the KES table is built from.

    The paper's protocol keeps θ_i + θ_r = 90°.  Denser data sets (several θ_i per
    γ) are reduced to the line closest to 90° among those with at least half the
    samples of the most populated line; the choice is recorded and the other samples
    stay available for validation.
    """
    total = np.round(np.degrees(m.theta_i[rows] + m.theta_r[rows]), 6)
    values, counts = np.unique(total, return_counts=True)
    candidates = values[counts >= 0.5 * counts.max()]
    best = candidates[np.argmin(np.abs(candidates - 90.0))]
    return float(np.radians(best))


def _merge_close(values, tol: float = 1e-12) -> np.ndarray:
    """Sorted unique values, merging neighbours closer than ``tol`` (keeps the first)."""
    v = np.unique(values)
    keep = np.concatenate([[True], np.diff(v) > tol])
    return v[keep]


def _line_weight(gamma, line_sum: float) -> np.ndarray:
    """√(cos θ_i cos θ_r) on the line θ_i + θ_r = S at deviation γ: √((cos γ + cos S)/2)."""
    return np.sqrt(np.clip((np.cos(gamma) + np.cos(line_sum)) / 2.0, 0.0, None))


def fit(
    m: Measurement,
    orientations: int | None = None,
    fallback: str = "error",
    body="auto",
    noise_floor="auto",
    interpolation: str = "kes",
    n_phi: int = DEFAULT_N_PHI,
    gamma_step=None,
) -> Model:
    """Build the extended-KES model from in-plane measurements.

    Parameters
    ----------
    m : Measurement
        Needs in-plane rows at ψ = 0, 45, 90° (and 135° for ``orientations=4``).
    orientations : {None, 3, 4}
        3 reproduces the paper's eq. 1–2; 4 (default when 135° was measured) uses
        all four orientations.
    fallback : {"error", "log"}
        What to do where K(φ) ≤ 0 between orientations (DESIGN §3).
    body : "auto", "none" or float
        Lambertian body term c in 1/sr (module docstring).
    noise_floor : "auto" or float
        Floor of q (same unit as q: 1/sr).
    interpolation : {"kes", "nearest", "linear"}
        Interpolation over φ; the last two are baselines.
    n_phi : int
        Number of φ cells of the table (multiple of 8 keeps the measured azimuths on
        the grid).
    gamma_step : float, optional
        γ step of the table, radians (default: the measured spacing, at most 1°).

    Returns
    -------
    Model
    """
    if fallback not in FALLBACKS:
        raise KESError(f"unknown fallback {fallback!r}; expected one of {', '.join(FALLBACKS)}")
    if interpolation not in INTERPOLATIONS:
        raise KESError(
            f"unknown interpolation {interpolation!r}; expected one of {', '.join(INTERPOLATIONS)}"
        )
    if n_phi % 8:
        raise KESError(f"expected n_phi to be a multiple of 8, got {n_phi}")
    orientations = _select_orientations(m, orientations)
    psis = np.radians([0.0, 45.0, 90.0, 135.0][:orientations])
    C = m.n_channels

    # 1. half-samples per orientation on one incidence line θ_i + θ_r = S
    in_plane = np.flatnonzero(m.is_in_plane)
    at = {k: in_plane[np.abs(m.psi[in_plane] - psi) < ORIENTATION_TOL] for k, psi in enumerate(psis)}
    line_sum = _incidence_line(m, np.concatenate(list(at.values())))
    curves = {}  # slot -> (|γ| sorted, f values (n, C))
    used_rows = []
    for k in range(orientations):
        rows = at[k][np.abs(m.theta_i[at[k]] + m.theta_r[at[k]] - line_sum) < 1e-6]
        used_rows.append(rows)
        gamma = m.theta_r[rows] - m.theta_i[rows]
        for slot, sign in ((k, 1.0), (k + 4, -1.0)):
            sel = sign * gamma >= -1e-12
            if not np.any(sel):
                raise MeasurementError(
                    f"{m.source or 'measurement'}: orientation psi = {np.degrees(psis[k]):g} deg has no "
                    f"samples with {'gamma >= 0' if sign > 0 else 'gamma <= 0'} on the line "
                    f"theta_i + theta_r = {np.degrees(line_sum):g} deg"
                )
            g = np.abs(gamma[sel])
            order = np.argsort(g)
            curves[slot] = (g[order], m.values[rows[sel]][order])
    used = np.concatenate(used_rows)
    values_used = m.values[used]

    # 2. body term
    if isinstance(body, str) and body == "auto":
        c = np.maximum(values_used.min(axis=0), 0.0)
        body_mode = "auto"
    elif isinstance(body, str) and body == "none":
        c = np.zeros(C)
        body_mode = "none"
    else:
        try:
            c = np.broadcast_to(np.asarray(body, float), (C,)).copy()
        except ValueError:
            raise KESError(f"expected body 'auto', 'none' or a number per channel, got {body!r}") from None
        body_mode = "value"

    # 3. q = f·√(cos θ_i cos θ_r) of every half-sample (body included: KES works on
    #    the measured quantity, as in the paper), floored at the noise level
    gamma_nodes = _merge_close(np.concatenate([curves[s][0] for s in curves]))
    slots = kes.half_slots(orientations)
    q_half_nodes = np.full((gamma_nodes.size, 8, C), np.nan)
    for slot in slots:
        g, f = curves[slot]
        q = f * _line_weight(g, line_sum)[:, None]
        for ch in range(C):
            q_half_nodes[:, slot, ch] = np.interp(gamma_nodes, g, q[:, ch])

    if isinstance(noise_floor, str) and noise_floor == "auto":
        peak = np.nanmax(q_half_nodes[:, slots, :], axis=(0, 1))
        floor = np.maximum(RELATIVE_NOISE_FLOOR * peak, np.finfo(float).tiny)
    else:
        floor = np.broadcast_to(np.asarray(noise_floor, float), (C,)).copy()
        if np.any(floor <= 0):
            raise KESError(f"expected a positive noise floor, got {noise_floor!r}")
    floored = []
    low = q_half_nodes[:, slots, :] < floor
    for gi, si, ch in np.argwhere(low):
        floored.append({
            "gamma_deg": round(float(np.degrees(gamma_nodes[gi])), 6),
            "azimuth_deg": round(float(np.degrees(kes.HALF_AZIMUTHS[slots[si]])), 6),
            "channel": m.channels[ch],
        })
    q_half_nodes[:, slots, :] = np.maximum(q_half_nodes[:, slots, :], floor)

    # 4. uniform γ grid containing the nodes
    gamma_grid = _gamma_grid(gamma_nodes, gamma_step)
    q_half = np.empty((gamma_grid.size, 8, C))
    for slot in slots:
        for ch in range(C):
            q_half[:, slot, ch] = np.interp(gamma_grid, gamma_nodes, q_half_nodes[:, slot, ch])
    if orientations == 3:
        q_half[:, [3, 7], :] = np.nan

    # 5. interpolate over φ at every γ, then split off the body: lobe = q − c·w(γ)
    phi_grid = np.arange(n_phi) * (2 * np.pi / n_phi)
    table, fallback_gamma = _fill_table(q_half, phi_grid, gamma_grid, orientations, interpolation, fallback)
    body_q = c[None, None, :] * _line_weight(gamma_grid, line_sum)[None, :, None]
    lobe = table - body_q
    clamped = int(np.count_nonzero(lobe < -1e-12 * np.abs(table)))
    table = np.maximum(lobe, 0.0)
    q_total_nodes = q_half_nodes
    q_half_nodes = q_half_nodes - c[None, None, :] * _line_weight(gamma_nodes, line_sum)[:, None, None]

    diagnostics = {
        "floored": floored,
        "noise_floor": floor.tolist(),
        "fallback_gamma_deg": [round(float(np.degrees(gamma_grid[i])), 6) for i in fallback_gamma],
        "unused_rows": int(len(m) - used.size),
        "incidence_line_deg": round(float(np.degrees(line_sum)), 6),
        "lobe_clamped": clamped,
        "gamma0_peaks": _gamma0_peaks(q_half_nodes, gamma_nodes, slots, m.channels),
    }
    if orientations == 4:
        diagnostics["residual_135"] = _residual_135(q_total_nodes, m.channels)
    return Model(
        channels=tuple(m.channels),
        phi_grid=phi_grid,
        gamma_grid=gamma_grid,
        table=table,
        body=c,
        gamma_nodes=gamma_nodes,
        q_nodes=q_half_nodes,
        kind="kes",
        parameters={
            "orientations": orientations,
            "fallback": fallback,
            "body": body_mode if body_mode != "value" else c.tolist(),
            "noise_floor": noise_floor if isinstance(noise_floor, str) else floor.tolist(),
            "interpolation": interpolation,
            "gamma_interpolation": "linear",
            "n_phi": n_phi,
        },
        diagnostics=diagnostics,
        input_info=m.input_info(),
    )


def _gamma_grid(nodes: np.ndarray, step) -> np.ndarray:
    gmax = float(nodes[-1])
    if gmax <= 0:
        raise MeasurementError("expected samples away from the mirror direction (|gamma| > 0), got only gamma = 0")
    if step is None:
        spacing = np.diff(nodes)
        uniform = spacing.size and np.allclose(spacing, spacing[0], rtol=1e-6, atol=1e-9) and np.isclose(nodes[0], 0.0, atol=1e-9)
        if uniform:
            step = spacing[0] / math.ceil(spacing[0] / MAX_GAMMA_STEP - 1e-9)
        else:
            step = math.radians(0.25)
    n = int(round(gmax / step))
    grid = np.linspace(0.0, n * step, n + 1)
    if grid[-1] < gmax - 1e-9:
        grid = np.append(grid, grid[-1] + step)
    return grid


def _fill_table(q_half, phi_grid, gamma_grid, orientations, interpolation, fallback):
    """q(φ, γ) table, shape (n_phi, n_gamma, C), and the γ indices that fell back."""
    slots = kes.half_slots(orientations)
    n_gamma, _, C = q_half.shape
    if interpolation == "nearest":
        az = kes.HALF_AZIMUTHS[slots]
        d = np.abs((phi_grid[:, None] - az[None, :] + np.pi) % (2 * np.pi) - np.pi)
        nearest = slots[np.argmin(d + 1e-9 * np.arange(slots.size), axis=1)]
        return np.transpose(q_half[:, nearest, :], (1, 0, 2)).copy(), []
    if interpolation == "linear":
        az = np.append(kes.HALF_AZIMUTHS[slots], 2 * np.pi)
        table = np.empty((phi_grid.size, n_gamma, C))
        for gi in range(n_gamma):
            for ch in range(C):
                vals = q_half[gi, slots, ch]
                table[:, gi, ch] = np.interp(phi_grid, az, np.append(vals, vals[0]))
        return table, []
    # KES on K = 1/q, vectorised over γ and channels
    K_half = 1.0 / q_half  # slots 3, 7 are NaN with 3 orientations and ignored
    K = kes.interpolate_circle(np.transpose(K_half, (0, 2, 1)), phi_grid, orientations)  # (γ, C, φ)
    bad = np.any(~(K > 0), axis=2)  # (γ, C)
    fallback_gamma = []
    if bad.any():
        bad_gamma = np.flatnonzero(bad.any(axis=1))
        if fallback == "error":
            g = bad_gamma[0]
            raise KESError(
                f"K(phi) = 1/rho <= 0 between the measured orientations at gamma = "
                f"{math.degrees(gamma_grid[g]):.4g} deg ({bad_gamma.size} gamma value(s) affected): "
                "warp and weft differ too much for the KES form; use fallback='log' "
                "(--fallback log) to interpolate log rho there instead"
            )
        fallback_gamma = bad_gamma.tolist()
        q_log = kes.interpolate_circle_log(
            np.transpose(q_half[bad_gamma], (0, 2, 1)), phi_grid, orientations
        )  # (nb, C, φ)
        K[bad_gamma] = 1.0 / q_log
    table = np.transpose(1.0 / K, (2, 0, 1))
    return np.ascontiguousarray(table), fallback_gamma


def _gamma0_peaks(q_nodes, gamma_nodes, slots, channels):
    """The measured q at γ = 0 per orientation: the φ discontinuity at the mirror."""
    if not np.isclose(gamma_nodes[0], 0.0, atol=1e-9):
        return {}
    peaks = q_nodes[0, [s for s in slots if s < 4], :]
    return {
        "q_deg": {f"{int(round(np.degrees(kes.HALF_AZIMUTHS[s])))}": peaks[i].tolist() for i, s in enumerate([s for s in slots if s < 4])},
        "max_over_min": (peaks.max(axis=0) / np.maximum(peaks.min(axis=0), np.finfo(float).tiny)).tolist(),
        "channels": list(channels),
    }


def _residual_135(q_nodes, channels):
    """How far the measured 135° is from the 3-orientation prediction (= 45°).

    Computed on the measured q (body included, floored), relative to the 45° value.
    """
    q45 = q_nodes[:, [1, 5], :]
    q135 = q_nodes[:, [3, 7], :]
    rel = (q135 - q45) / np.maximum(np.abs(q45), np.finfo(float).tiny)
    return {
        ch: {
            "max_abs_rel": float(np.max(np.abs(rel[..., i]))),
            "rms_rel": float(np.sqrt(np.mean(rel[..., i] ** 2))),
        }
        for i, ch in enumerate(channels)
    }
