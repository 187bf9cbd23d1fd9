"""Sampling for the paper's figures: the arrays they plot, computed through the core API.

Measured in-plane samples grouped by orientation (:func:`measured_in_plane`), the
model at the paper's in-plane geometry converted to the KES quantity
q = f_r·√(cos θ_i cos θ_r) (:func:`model_in_plane`, paper eq. 3), hemisphere pixel
grids (:func:`hemisphere_grid`), channel selection.  Every model kind is sampled through
:func:`kesbrdf.models.brdf.evaluate` and its (φ, γ) table view
(:meth:`kesbrdf.models.base.ReflectanceModel.table_view`).  Drawn by
:mod:`kesbrdf.plotting.drawing`, assembled by :mod:`kesbrdf.plotting.figures`.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import KesbrdfError, validate_choice
from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG

__all__ = [
    "PAPER_PSI_DEG",
    "PSI_TOL_DEG",
    "GAMMA_TOL_DEG",
    "LIGHT_TOL_DEG",
    "GAMMA_LIMIT_DEG",
    "select_channel",
    "measured_in_plane",
    "model_in_plane",
    "hemisphere_grid",
    "measured_at_light",
    "measured_at_gamma",
    "orientations_deg",
    "channels_of",
    "curve_gamma_max",
    "require_input",
    "disk_positions",
    "disk_position",
    "difference_map",
    "albedo_grid",
]

#: The paper's orientations, degrees.
PAPER_PSI_DEG = PAPER_ORIENTATIONS_DEG
#: Two in-plane samples belong to the same orientation when their ψ differ by less
#: than this (degrees); files store ψ with at most a few decimals.
PSI_TOL_DEG = 1e-3
#: A sample is "at" a requested γ when within this many degrees (the protocol's γ
#: step is 6°, so half a degree picks exactly one sample per orientation).
GAMMA_TOL_DEG = 0.5
#: A measured sample belongs to a Fig. 6 light when its light direction is within this
#: angle (degrees) of it; goniometers position to a fraction of a degree.
LIGHT_TOL_DEG = 1.0
#: Largest |γ| drawn for a model curve: at |γ| = 90° the paper geometry is grazing.
GAMMA_LIMIT_DEG = 89.0


def select_channel(values, channels, channel=None) -> tuple[np.ndarray, str]:
    """Pick one channel from ``values`` (..., C).

    Parameters
    ----------
    values : array_like, shape (..., C)
    channels : sequence of str
        Channel names of the last axis.
    channel : int, str or None
        Index or name; ``None`` takes the only channel, or the mean over channels.

    Returns
    -------
    (ndarray (...), str)
        The values and a label for them.

    >>> v, name = select_channel(np.array([[1.0, 3.0]]), ("R", "G"))
    >>> v.tolist(), name
    ([2.0], 'mean(R, G)')
    """
    values = np.asarray(values, float)
    channels = tuple(channels)
    if channel is None:
        if values.shape[-1] == 1:
            return values[..., 0], channels[0]
        return values.mean(axis=-1), f"mean({', '.join(channels)})"
    if isinstance(channel, str):
        if channel in channels:
            return values[..., channels.index(channel)], channel
        if channel.lstrip("-").isdigit():
            channel = int(channel)
        else:
            raise KesbrdfError(f"expected a channel in {list(channels)}, got {channel!r}")
    index = int(channel)
    if not -len(channels) <= index < len(channels):
        raise KesbrdfError(f"expected a channel index below {len(channels)}, got {index}")
    return values[..., index], channels[index]


def measured_in_plane(measurement, channel=None, paper_line: str | bool = "auto") -> dict:
    """The in-plane samples of a measurement grouped by orientation, as q over signed γ.

    Parameters
    ----------
    measurement : Measurement
    channel : int, str or None
        See :func:`select_channel`.
    paper_line : "auto", True or False
        Keep only samples on the paper's line θ_i + θ_r = 90° (``True``), all in-plane
        samples (``False``), or the paper line when the data has any (``"auto"``).

    Returns
    -------
    dict
        ``psi_deg`` (P,), ``gamma_deg`` (P, N) and ``q`` (P, N) with NaN padding,
        sorted by γ within each orientation; ``label`` (channel name).

    Raises
    ------
    KesbrdfError
        If the measurement has no in-plane samples.
    """
    inplane = measurement.is_in_plane
    if not inplane.any():
        raise KesbrdfError(
            f"{measurement.source or 'measurement'}: expected in-plane samples (psi_deg) "
            "for this figure, got only general samples"
        )
    q, label = select_channel(measurement.q, measurement.channels, channel)
    theta_sum = measurement.theta_i + measurement.theta_r
    on_line = inplane & np.isclose(theta_sum, np.pi / 2, atol=np.radians(1e-3))
    keep = on_line if (paper_line is True or (paper_line == "auto" and on_line.any())) else inplane
    psi_deg = np.degrees(measurement.psi[keep])
    gamma_deg = np.degrees(measurement.gamma[keep])
    q = q[keep]
    key = np.round(psi_deg / PSI_TOL_DEG).astype(np.int64)
    groups, inverse = np.unique(key, return_inverse=True)
    counts = np.bincount(inverse, minlength=groups.size)
    order = np.lexsort((gamma_deg, inverse))
    n_max = int(counts.max())
    slot = np.arange(order.size) - np.repeat(np.cumsum(counts) - counts, counts)
    G = np.full((groups.size, n_max), np.nan)
    Q = np.full((groups.size, n_max), np.nan)
    G[inverse[order], slot] = gamma_deg[order]
    Q[inverse[order], slot] = q[order]
    return {"psi_deg": groups * PSI_TOL_DEG, "gamma_deg": G, "q": Q, "label": label}


def model_in_plane(model, psi, gamma, mapping: str | None = None) -> np.ndarray:
    """The model's q at the paper's in-plane geometry for orientation ψ and signed γ.

    θ_i = π/4 − γ/2, θ_r = π/4 + γ/2, light at azimuth ψ + π, viewer at ψ
    (docs/method.md, "Conventions"); returns ``evaluate(model, wi, wr, mapping) · √(cos θ_i cos θ_r)``.

    Parameters
    ----------
    model : Model
    psi, gamma : array_like
        Radians, broadcast together; |γ| < π/2.
    mapping : str
        Passed to :func:`kesbrdf.models.brdf.evaluate`.

    Returns
    -------
    ndarray, shape (..., C)
    """
    from kesbrdf.models import brdf
    from kesbrdf.geometry import in_plane_directions

    psi, gamma = np.broadcast_arrays(np.asarray(psi, float), np.asarray(gamma, float))
    theta_i = np.pi / 4 - gamma / 2
    theta_r = np.pi / 4 + gamma / 2
    wi, wr = in_plane_directions(psi, theta_i, theta_r)
    f_r = np.asarray(brdf.evaluate(model, wi, wr, mapping=mapping), float)
    return f_r * np.sqrt(np.cos(theta_i) * np.cos(theta_r))[..., None]


def hemisphere_grid(n: int, projection: str = "equal-area") -> dict:
    """Pixel grid over the unit disk and the viewing directions it shows.

    Parameters
    ----------
    n : int
        Pixels per side.
    projection : {"equal-area", "theta-linear"}
        Disk radius r of a direction at polar angle θ: ``equal-area`` (Lambert)
        r = √2·sin(θ/2), ``theta-linear`` r = θ/(π/2).  r = 1 at the horizon; the disk's
        x axis is the warp, y the weft (top view).

    Returns
    -------
    dict
        ``u, v, theta, phi`` (n, n) (row = v index from −1 up), ``inside`` (n, n) bool,
        ``extent`` for imshow, ``label`` describing the projection.
    """
    validate_choice("projection", projection, ("equal-area", "theta-linear"))
    c = np.linspace(-1.0, 1.0, n)
    half = 1.0 / (n - 1) if n > 1 else 1.0
    u, v = np.meshgrid(c, c)
    r = np.hypot(u, v)
    inside = r < 1.0
    rc = np.minimum(r, 1.0)
    if projection == "equal-area":
        theta = 2.0 * np.arcsin(rc / np.sqrt(2.0))
        label = r"[equal-area, $r=\sqrt{2}\sin(\theta_r/2)$]"
    else:
        theta = rc * np.pi / 2
        label = r"[$r=\theta_r/90°$]"
    return {
        "u": u,
        "v": v,
        "theta": theta,
        "phi": np.arctan2(v, u),
        "inside": inside,
        "extent": (-1 - half, 1 + half, -1 - half, 1 + half),
        "label": label,
        "projection": projection,
    }


def disk_positions(theta, phi, projection: str):
    """Disk coordinates (u, v) of directions (θ, φ) in a :func:`hemisphere_grid` projection."""
    theta = np.asarray(theta, float)
    r = np.sqrt(2.0) * np.sin(theta / 2) if projection == "equal-area" else theta / (np.pi / 2)
    return r * np.cos(phi), r * np.sin(phi)


def disk_position(theta, phi, projection: str):
    u, v = disk_positions(theta, phi, projection)
    return float(u), float(v)


def require_input(obj, what: str, figure: str):
    if obj is None:
        raise KesbrdfError(f"figure {figure}: expected a {what}, got none")
    return obj


def curve_gamma_max(model) -> float:
    """Largest |γ| of a model curve: the model's table's (its tabulated view for kinds
    without one), at most :data:`GAMMA_LIMIT_DEG` (that limit for a kind with no view)."""
    from kesbrdf.errors import ModelError

    try:
        g_max = float(np.max(model.table_view().gamma_grid))
    except ModelError:  # a kind that cannot be tabulated: its curves still evaluate
        g_max = np.inf
    return float(min(g_max, np.radians(GAMMA_LIMIT_DEG)))


def channels_of(model):
    return tuple(getattr(model, "channels", ("value",)))


def orientations_deg(measured: dict | None) -> np.ndarray:
    if measured is not None:
        return np.asarray(measured["psi_deg"], float)
    return np.asarray(PAPER_PSI_DEG)


def measured_at_gamma(measured: dict, gamma_deg: float):
    """Measured (angle, q) at signed γ: ψ with γ, and ψ + 180° with −γ (docs/method.md, "From the table to a BRDF")."""
    phis, values = [], []
    for sign, offset in ((1.0, 0.0), (-1.0, 180.0)):
        # at γ = 0 both halves are the same sample, drawn at ψ and at ψ + 180°
        dist = np.abs(measured["gamma_deg"] - sign * gamma_deg)
        dist = np.where(np.isfinite(dist), dist, np.inf)
        j = np.argmin(dist, axis=1)
        rows = np.arange(dist.shape[0])
        hit = dist[rows, j] <= GAMMA_TOL_DEG
        phis.append(measured["psi_deg"][hit] + offset)
        values.append(measured["q"][rows, j][hit])
    return np.radians(np.concatenate(phis)), np.concatenate(values)


def difference_map(model_values, truth, kind: str):
    """log10(model / truth) or (model − truth) / truth; NaN where undefined."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if kind == "log":
            ok = (model_values > 0) & (truth > 0)
            return np.where(ok, np.log10(np.where(ok, model_values, 1.0) / np.where(ok, truth, 1.0)), np.nan)
        ok = truth > 0
        return np.where(ok, (model_values - truth) / np.where(ok, truth, 1.0), np.nan)


def measured_at_light(measurement, theta_i, phi_i, tol=np.radians(LIGHT_TOL_DEG)):
    """Rows of ``measurement`` whose light is within ``tol`` (radians) of (θ_i, φ_i).

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    from kesbrdf.geometry import spherical_to_cartesian

    wi = spherical_to_cartesian(theta_i, phi_i)
    cos_angle = np.clip(measurement.wi @ wi, -1.0, 1.0)
    return (np.arccos(cos_angle) <= tol) & (measurement.theta_r < np.pi / 2)


def albedo_grid(diagnostics):
    """(θ_i°, φ_i°, albedo (T, P)) from a diagnostics dict, or None."""
    alb = diagnostics.get("albedo") if isinstance(diagnostics, dict) else None
    if not isinstance(alb, dict):
        return None
    t = alb.get("theta_i_deg")
    a = alb.get("albedo", alb.get("values"))
    if t is None or a is None:
        return None
    t = np.atleast_1d(np.asarray(t, float))
    a = np.asarray(a, float)
    p = alb.get("phi_i_deg")
    p = np.zeros(1) if p is None else np.atleast_1d(np.asarray(p, float))
    if a.ndim == 3 or (a.ndim == 2 and a.shape != (t.size, p.size)):
        a = a.reshape(t.size, p.size, -1).mean(axis=-1)
    return t, p, a.reshape(t.size, p.size)

