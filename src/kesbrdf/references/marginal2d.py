r"""The continuous piecewise-linear 2-D warp of the RGL tensor files, in numpy.

Dupuy & Jakob 2018 (sec. 4) parameterise a measured BRDF by warping the unit square
with the visible-normal distribution.  Mitsuba 3 implements the warp as
``Marginal2D<Float, Dim, Continuous=true>`` (``include/mitsuba/core/distr_2d.h``;
Python ``mi.MarginalContinuous2D0..3``); pbrt-v4's ``PiecewiseLinear2D`` is the same
construction.  The reader of a ``.bsdf`` (Mitsuba ``measured``) and its writer
(:mod:`kesbrdf.export.rgl_bsdf`) must use the same warp, so this module re-implements
exactly that construction (written from the description and checked against
Mitsuba's bindings in ``tests/export/test_marginal2d.py``):

* the density p(x, y) is the *bilinear* interpolant of the grid values
  d[j, i] at nodes (x_i, y_j) = (i/(W−1), j/(H−1)), normalised so ∫∫p = 1 (optional);
* the conditional CDF along x is the exact integral of the linear interpolant of each
  row (trapezoids), the marginal CDF along y the exact integral of the row totals,
  which are themselves linear in y between rows;
* sampling inverts the marginal (a quadratic per segment), then the conditional of the
  row interpolated at that y (another quadratic); :meth:`Marginal2D.invert` is the
  exact inverse and :meth:`Marginal2D.eval` the bilinear density;
* conditional warps (parameters such as (φ_i, θ_i)) interpolate the per-slice
  normalised densities *and CDFs* multilinearly in the parameters, the last parameter
  varying fastest in the data (C order ``data[p0, p1, ..., y, x]``); a parameter
  outside its range is clamped.

Computation is in float64; Mitsuba stores float32, so results agree to ~1e-6.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Marginal2D"]

#: Mitsuba's dr::Epsilon<float>: samples are kept this far inside the unit square.
EPS32 = 2.0**-24


def _sample_segment(s, inv_width, v0, v1):
    """Invert ∫_0^t lerp(v0, v1, τ/w) dτ = s for t/w (a quadratic)."""
    non_const = np.abs(v0 - v1) > 1e-4 * (v0 + v1)
    divisor = np.where(non_const, v0 - v1, v0 + v1)
    s = s * 2.0 * inv_width
    s = np.where(non_const, v0 - np.sqrt(np.maximum(v0 * v0 + s * (v1 - v0), 0.0)), s)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(divisor != 0, s / np.where(divisor != 0, divisor, 1.0), s)


def _invert_segment(t, width, v0, v1):
    return t * (v0 + (v1 - v0) * 0.5 * t) * width


class Marginal2D:
    """Continuous marginal/conditional warp of a bilinear density (module docstring).

    Parameters
    ----------
    data : array_like, shape (N0, ..., N_{D-1}, H, W)
        Density values at the grid nodes, one (H, W) slice per parameter node.
    param_values : sequence of D 1-D arrays
        The parameter nodes (ascending), one array per leading axis of ``data``.
    normalize : bool
        Scale each slice to integrate to one (Mitsuba's default).
    sampling : bool
        Build the CDFs (needed by :meth:`sample` and :meth:`invert`).
    """

    def __init__(self, data, param_values=(), normalize: bool = True, sampling: bool = True):
        data = np.asarray(data, float)
        self.n_params = len(param_values)
        if data.ndim != 2 + self.n_params:
            raise ValueError(f"expected data with {2 + self.n_params} axes, got shape {data.shape}")
        self.param_values = [np.asarray(v, float).ravel() for v in param_values]
        self.param_res = data.shape[: self.n_params]
        for v, n in zip(self.param_values, self.param_res):
            if v.size != n:
                raise ValueError(f"expected {n} parameter values, got {v.size}")
        self.H, self.W = data.shape[-2:]
        if self.H < 2 or self.W < 2:
            raise ValueError(f"expected a grid of at least 2 x 2, got {self.H} x {self.W}")
        strides, s = [0] * self.n_params, 1
        for d in range(self.n_params - 1, -1, -1):
            strides[d] = s if self.param_res[d] > 1 else 0
            s *= self.param_res[d]
        self.strides = strides
        d = data.reshape(-1, self.H, self.W)
        self.normalized = normalize
        norm = np.ones(d.shape[0])
        if sampling:
            cond = np.cumsum(0.5 / (self.W - 1) * (d[:, :, 1:] + d[:, :, :-1]), axis=2)  # (S, H, W-1)
            rows = cond[:, :, -1]
            marg = np.cumsum(0.5 / (self.H - 1) * (rows[:, 1:] + rows[:, :-1]), axis=1)  # (S, H-1)
            if normalize:
                norm = 1.0 / marg[:, -1]
            self.cond = cond * norm[:, None, None]
            self.marg = marg * norm[:, None]
        elif normalize:
            total = (d[:, 1:, 1:] + d[:, 1:, :-1] + d[:, :-1, 1:] + d[:, :-1, :-1]).sum(axis=(1, 2))
            norm = 1.0 / (total * 0.25 / ((self.W - 1) * (self.H - 1)))
        self.data = d * norm[:, None, None]

    # -- parameter interpolation -------------------------------------------------------
    def _corners(self, params, n):
        """Slice indices (K, n) and weights (K, n) of the 2^D corners around ``params``."""
        idx = [np.zeros(n, int)]
        wts = [np.ones(n)]
        for d in range(self.n_params):
            v = self.param_values[d]
            if v.size == 1:
                continue
            p = np.broadcast_to(np.asarray(params[d], float), (n,))
            i = np.clip(np.searchsorted(v, p, side="left") - 1, 0, v.size - 2)
            w1 = np.clip((p - v[i]) / (v[i + 1] - v[i]), 0.0, 1.0)
            idx = [k + i * self.strides[d] for k in idx] + [k + (i + 1) * self.strides[d] for k in idx]
            wts = [w * (1 - w1) for w in wts] + [w * w1 for w in wts]
        return np.array(idx), np.array(wts)

    @staticmethod
    def _lookup(table, corners, *index):
        """Σ_k w_k table[slice_k, index...]: the multilinear interpolant over parameters."""
        idx, wts = corners
        return np.einsum("kn,kn->n", wts, table[(idx,) + tuple(np.broadcast_to(i, idx.shape) for i in index)])

    def _n(self, pos, params):
        pos = np.asarray(pos, float).reshape(-1, 2)
        return pos, self._corners(params if self.n_params else (), pos.shape[0])

    # -- the three operations ----------------------------------------------------------
    def eval(self, pos, params=()) -> np.ndarray:
        """Density at ``pos`` (n, 2) = (x, y) for parameters ``params`` (D arrays of n)."""
        pos, c = self._n(pos, params)
        p = np.clip(pos, 0.0, 1.0) * (self.W - 1, self.H - 1)
        o = np.minimum(p.astype(int), (self.W - 2, self.H - 2))
        t = p - o
        ox, oy = o[:, 0], o[:, 1]
        v00 = self._lookup(self.data, c, oy, ox)
        v10 = self._lookup(self.data, c, oy, ox + 1)
        v01 = self._lookup(self.data, c, oy + 1, ox)
        v11 = self._lookup(self.data, c, oy + 1, ox + 1)
        tx, ty = t[:, 0], t[:, 1]
        return (v00 * (1 - tx) + v10 * tx) * (1 - ty) + (v01 * (1 - tx) + v11 * tx) * ty

    def sample(self, u, params=()):
        """Warp uniform ``u`` (n, 2) to the density: returns (points (n, 2), pdf (n,))."""
        u, c = self._n(u, params)
        n = u.shape[0]
        u = np.clip(u, EPS32, 1.0 - EPS32)
        x, y = u[:, 0].copy(), u[:, 1].copy()
        H, W = self.H, self.W
        idx, wts = c
        marg = np.einsum("kn,knj->nj", wts, self.marg[idx])  # (n, H-1)
        if not self.normalized:
            y = y * marg[:, -1]
        row = np.minimum((marg[:, : H - 2] < y[:, None]).sum(axis=1), H - 2)
        ar = np.arange(n)
        y = y - np.where(row > 0, marg[ar, np.maximum(row - 1, 0)], 0.0)
        cond0 = np.einsum("kn,knj->nj", wts, self.cond[idx, row[None, :]])  # (n, W-1)
        cond1 = np.einsum("kn,knj->nj", wts, self.cond[idx, row[None, :] + 1])
        r0, r1 = cond0[:, -1], cond1[:, -1]
        y = _sample_segment(y, H - 1, r0, r1)
        x = x * (r0 + (r1 - r0) * y)
        fc = cond0 + (cond1 - cond0) * y[:, None]
        col = np.minimum((fc[:, : W - 1] < x[:, None]).sum(axis=1), W - 2)
        x = x - np.where(col > 0, fc[ar, np.maximum(col - 1, 0)], 0.0)
        v00 = self._lookup(self.data, c, row, col)
        v10 = self._lookup(self.data, c, row, col + 1)
        v01 = self._lookup(self.data, c, row + 1, col)
        v11 = self._lookup(self.data, c, row + 1, col + 1)
        c0 = v00 + (v01 - v00) * y
        c1 = v10 + (v11 - v10) * y
        x = _sample_segment(x, W - 1, c0, c1)
        pts = np.stack([(col + x) / (W - 1), (row + y) / (H - 1)], axis=-1)
        return pts, c0 + (c1 - c0) * x

    def invert(self, pos, params=()):
        """Inverse of :meth:`sample`: returns (uniform points (n, 2), pdf (n,))."""
        pos, c = self._n(pos, params)
        H, W = self.H, self.W
        p = np.clip(pos, 0.0, 1.0) * (W - 1, H - 1)
        o = np.minimum(p.astype(int), (W - 2, H - 2))
        t = p - o
        ox, oy = o[:, 0], o[:, 1]
        tx, ty = t[:, 0], t[:, 1]
        v00 = self._lookup(self.data, c, oy, ox)
        v10 = self._lookup(self.data, c, oy, ox + 1)
        v01 = self._lookup(self.data, c, oy + 1, ox)
        v11 = self._lookup(self.data, c, oy + 1, ox + 1)
        c0 = v00 + (v01 - v00) * ty
        c1 = v10 + (v11 - v10) * ty
        pdf = c0 + (c1 - c0) * tx
        x = _invert_segment(tx, 1.0 / (W - 1), c0, c1)
        prev = np.maximum(ox - 1, 0)
        f0 = self._lookup(self.cond, c, oy, prev)
        f1 = self._lookup(self.cond, c, oy + 1, prev)
        x = x + np.where(ox > 0, f0 + (f1 - f0) * ty, 0.0)
        r0 = self._lookup(self.cond, c, oy, W - 2)
        r1 = self._lookup(self.cond, c, oy + 1, W - 2)
        x = x / (r0 + (r1 - r0) * ty)
        y = _invert_segment(ty, 1.0 / (H - 1), r0, r1)
        y = y + np.where(oy > 0, self._lookup(self.marg, c, np.maximum(oy - 1, 0)), 0.0)
        if not self.normalized:
            y = y / self._lookup(self.marg, c, H - 2)
        return np.stack([x, y], axis=-1), pdf
