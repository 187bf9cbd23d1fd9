r"""The tabulated lobe q(φ, γ): the one table format every table consumer reads.

A table holder has ``phi_grid`` (n_phi,) = j·2π/n_phi, ``gamma_grid`` (n_gamma,) =
k·Δγ from 0 and ``table`` (n_phi, n_gamma, C).  The ``kes`` kind *is* such a table
(:mod:`kesbrdf.models.kes`); the fibre prior's residual is one; and every other kind
gets one through :func:`tabulate`, so the figures that read the table (paper Fig. 5),
the shaders (GLSL of the BRDF Explorer, the viewer, the ``kesbrdf`` Mitsuba plugin) and
the exports work on any kind (:meth:`kesbrdf.models.base.ReflectanceModel.table_view`).

Lookup (``docs/formats.md``, step 2): bilinear in (φ, γ), φ periodic, γ clamped to
[0, γ_max].

Tabulation of a kind without a (φ, γ) table (:func:`tabulate`): the model is evaluated
on the paper's incidence line θ_i + θ_r = 90° (θ_i = 45° − γ/2, θ_r = 45° + γ/2, light
at azimuth φ + π, viewer at φ), where the KES mapping (paper eq. 3–4, deviation form)
sends the pair to exactly (φ, γ).  The body c is the smallest f_r over the grid per
channel (clipped at 0: eq. B1 of :mod:`kesbrdf.models.body`, as the ``kes`` fit's ``body="auto"``); the table holds the lobe
q = (f_r − c)·w(γ) with the ``bounded`` line weight w
(:func:`kesbrdf.models.mappings.line_foreshortening`).  The table reproduces the model
at the grid nodes of that line; off the line it is the KES mapping's reading of it,
which is what a table can hold (docs/models.md).
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import ModelError, where
from kesbrdf.models.body import body_bound

__all__ = [
    "lookup",
    "lookup_unit",
    "check_uniform_grid",
    "check_values",
    "gamma0_behaviour",
    "tabulate",
    "GRID_TOL",
    "TABLE_N_PHI",
    "TABLE_N_GAMMA",
    "TABLE_GAMMA_MAX_DEG",
]

#: Grid values may differ from the uniform grid the lookup assumes by this much (radians).
GRID_TOL = 1e-9
#: Default φ cells of a tabulated view: 1°, the ``kes`` fit's default (a multiple of 8
#: keeps the orientations k·45° on the grid).
TABLE_N_PHI = 360
#: Default γ nodes of a tabulated view (1° steps from 0 to :data:`TABLE_GAMMA_MAX_DEG`).
TABLE_N_GAMMA = 89
#: Largest γ of a tabulated view: on the paper's line θ_r = 45° + γ/2 reaches the
#: horizon at γ = 90°.
TABLE_GAMMA_MAX_DEG = 88.0


def check_uniform_grid(grid: np.ndarray, step: float, name: str, source=None) -> None:
    """A one-line :class:`ModelError` unless ``grid`` is k·step, k = 0, 1, ... (within GRID_TOL)."""
    with np.errstate(over="ignore", invalid="ignore"):
        expected = np.arange(grid.size) * step
    if not (np.all(np.isfinite(grid)) and np.allclose(grid, expected, rtol=0, atol=GRID_TOL)):
        raise ModelError(
            f"{where(source)}{name}: expected the uniform grid k*{step:.6g} from 0 ({grid.size} values), "
            f"got {grid[:3].tolist()}..."
        )


def check_values(a: np.ndarray, name: str, source=None) -> None:
    """A one-line :class:`ModelError` unless ``a`` is finite and ≥ 0."""
    bad = ~(np.isfinite(a) & (a >= 0))
    if bad.any():
        first = a[bad].flat[0]
        raise ModelError(
            f"{where(source)}{name}: expected finite non-negative values, got {int(bad.sum())} bad value(s), "
            f"e.g. {float(first)!r}"
        )


def lookup_unit(holder, phi, gamma) -> np.ndarray:
    """Bilinear lookup for φ ∈ [0, 2π], γ ≥ 0 (finite), shape (n, C).

    The table is read flattened with ``np.take``; see :func:`lookup` for the general
    version.
    """
    T = holder.table
    n_phi, n_gamma, C = T.shape
    u = phi * (n_phi / (2 * np.pi))
    i0 = u.astype(np.intp)  # u ≥ 0: truncation is floor
    fu = u - i0
    i0[i0 >= n_phi] -= n_phi
    i1 = i0 + 1
    i1[i1 == n_phi] = 0
    dgamma = holder.gamma_grid[1] - holder.gamma_grid[0]
    v = np.minimum(gamma, holder.gamma_grid[-1]) / dgamma
    j0 = np.minimum(v.astype(np.intp), n_gamma - 1)
    fv = v - j0
    dj = (j0 < n_gamma - 1).astype(np.intp)
    i0 *= n_gamma
    i0 += j0
    i1 *= n_gamma
    i1 += j0
    if C == 1:
        flat = T.reshape(-1)
        t00 = np.take(flat, i0)
        t10 = np.take(flat, i1)
        i0 += dj
        i1 += dj
        t01 = np.take(flat, i0)
        t11 = np.take(flat, i1)
    else:
        flat = T.reshape(-1, C)
        fu = fu[:, None]
        fv = fv[:, None]
        t00 = np.take(flat, i0, axis=0)
        t10 = np.take(flat, i1, axis=0)
        i0 += dj
        i1 += dj
        t01 = np.take(flat, i0, axis=0)
        t11 = np.take(flat, i1, axis=0)
    gu = 1.0 - fu
    t00 *= gu
    t10 *= fu
    t00 += t10
    t01 *= gu
    t11 *= fu
    t01 += t11
    t00 *= 1.0 - fv
    t01 *= fv
    t00 += t01
    return t00.reshape(-1, C)


def lookup(holder, phi, gamma) -> np.ndarray:
    """Bilinear lookup of the lobe table q at (φ, γ) (docs/formats.md, step 2).

    Parameters
    ----------
    holder
        Any table holder (``phi_grid``, ``gamma_grid``, ``table``): a ``kes`` model, a
        tabulated view, the prior's residual.
    phi, gamma : array_like
        Radians; φ is periodic, γ is clamped to [0, γ_max].  Broadcast together.
        NaN in gives NaN out.

    Returns
    -------
    ndarray, shape (..., C)
    """
    phi, gamma = np.broadcast_arrays(np.asarray(phi, float), np.asarray(gamma, float))
    shape = phi.shape
    phi = np.mod(phi.reshape(-1), 2 * np.pi)
    gamma = np.clip(gamma.reshape(-1), 0.0, None)
    nan = ~(np.isfinite(phi) & np.isfinite(gamma))
    q = lookup_unit(holder, np.where(nan, 0.0, phi), np.where(nan, 0.0, gamma))
    q[nan] = np.nan
    return q.reshape(shape + (holder.table.shape[-1],))


def gamma0_behaviour(holder) -> dict:
    """How the lobe varies with φ as γ → 0: the four measured peaks differ, so φ is
    a discontinuity at the mirror direction (docs/models.md).  Reports max/min of q over
    φ at the first grid γ values."""
    out = {}
    for gamma in holder.gamma_grid[:3]:
        q = lookup(holder, holder.phi_grid, np.full(holder.phi_grid.shape, gamma))
        qmin = np.maximum(q.min(axis=0), np.finfo(float).tiny)
        out[f"{np.degrees(gamma):.3g}"] = (q.max(axis=0) / qmin).tolist()
    diagnostics = getattr(holder, "diagnostics", None) or {}
    return {"q_max_over_min_by_gamma_deg": out, "measured_peaks": diagnostics.get("gamma0_peaks", {})}


def tabulate(model, n_phi: int | None = None, n_gamma: int | None = None):
    """The (φ, γ) table of any model, through its ``evaluate`` (module docstring).

    Returns the keyword fields of a model of the ``kes`` kind (the table format; its
    class builds the model, :meth:`kesbrdf.models.kes.Model.tabulate`), whose
    ``parameters`` record ``tabulated_from`` (the source kind) and the mapping it is read
    with off the line (:data:`kesbrdf.models.mappings.FIT_MAPPING`, as a new kes fit), and
    whose evaluation equals ``model``'s at the grid nodes of the paper's incidence line.  This module
    imports no kind, so the kinds can borrow from it without an import loop.
    """
    from kesbrdf.geometry import in_plane_directions
    from kesbrdf.models.mappings import FIT_MAPPING, line_foreshortening

    n_phi = TABLE_N_PHI if n_phi is None else int(n_phi)
    n_gamma = TABLE_N_GAMMA if n_gamma is None else int(n_gamma)
    if n_phi < 8 or n_phi % 8 or n_gamma < 2:
        raise ModelError(f"a tabulated view needs n_phi a multiple of 8 and n_gamma >= 2, got {n_phi} and {n_gamma}")
    phi_grid = np.arange(n_phi) * (2 * np.pi / n_phi)
    gamma_grid = np.arange(n_gamma) * (math.radians(TABLE_GAMMA_MAX_DEG) / (n_gamma - 1))
    psi, gamma = np.meshgrid(phi_grid, gamma_grid, indexing="ij")
    wi, wr = in_plane_directions(psi, np.pi / 4 - gamma / 2, np.pi / 4 + gamma / 2)
    f = np.asarray(model.evaluate(wi, wr), float)
    f = np.where(np.isfinite(f), f, 0.0)
    body = body_bound(f.reshape(-1, f.shape[-1]))  # kesbrdf.models.body, eq. B1
    w = line_foreshortening(gamma_grid, math.pi / 2, "bounded")
    table = np.ascontiguousarray(np.maximum(f - body, 0.0) * w[None, :, None])
    q_nodes = np.transpose(table[:: n_phi // 8], (1, 0, 2)).copy()  # (n_gamma, 8, C) at k·45°
    return dict(
        channels=tuple(model.channels),
        phi_grid=phi_grid,
        gamma_grid=gamma_grid,
        table=table,
        body=body,
        gamma_nodes=gamma_grid.copy(),
        q_nodes=q_nodes,
        parameters={
            "orientations": 4,
            "fallback": "log",
            "body": body.tolist(),
            "noise_floor": "none",
            "interpolation": "kes",
            "gamma_interpolation": "linear",
            "n_phi": n_phi,
            "normalisation": "bounded",
            "extrapolation": "fade",
            "mapping": FIT_MAPPING,
            "tabulated_from": model.kind,
        },
        diagnostics={"incidence_line_deg": 90.0, "warnings": []},
        input_info=dict(getattr(model, "input_info", {}) or {}),
        kesbrdf_version=getattr(model, "kesbrdf_version", None),
    )
