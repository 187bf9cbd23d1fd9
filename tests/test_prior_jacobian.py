"""The analytic Jacobian of the fibre prior (kesbrdf.models.fibre_physics.evaluate_with_jacobian)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from kesbrdf.models.fibre_physics import (FibrePrior, PriorSpec, _Data, _residual_jacobian, _residuals_batch, _solve, evaluate_batch,
                           evaluate_with_jacobian)

SEED = 11
VARIANTS = [("filament", "filament"), ("filament", "staple"), ("staple", "filament"), ("staple", "staple")]
# Central differences of step h·max(1, |θ|) have truncation error h²|f'''|/6. The
# sharpest factor is the tilt profile's logistic edge of width s ≥ 2° here (0.035 rad):
# |f'''/f'| ≲ 1/s² ≈ 800, so with h = 1e-5 the relative error is ≲ 1e-7; rounding adds
# 1e-16/h ≈ 1e-11. 1e-5 leaves two orders of margin for the products of several factors.
FD_STEP = 1e-5
ANALYTIC_RTOL = 1e-5
# The axis offset δ is a one-sided difference of step GEOMETRY_STEP = 1e-7: truncation
# h|f''|/2 ≲ 1e-7·10³ = 1e-4 relative (1/|n·h'| makes |f''/f'| up to ~10³). 1e-3 bounds
# that with margin and still fails a wrong sign, factor or column.
GEOMETRY_RTOL = 1e-3
# The staple sum is only piecewise smooth in ψ and δ: a tilt node drops out where
# |D| → 1 or |v*| → π/2, a jump. A difference whose step straddles one is meaningless, so
# the ψ and δ columns are compared on the samples where central differences of steps
# 1e-6 and 1e-5 agree (smooth there; the analytic ψ column is then held to
# ANALYTIC_RTOL against the 1e-6 one); at least this fraction must remain.
GEOMETRY_SMOOTH_FRACTION = 0.9
GEOMETRY_FD_STEPS = (1e-6, 1e-5)


def random_theta(spec: PriorSpec, rng) -> np.ndarray:
    """A random parameter vector inside the bounds, with profile edges no sharper than 2°."""
    lo, hi = spec.bounds()
    x = rng.uniform(lo, hi)
    for i, n in enumerate(spec.names()):
        if "log_k" in n:
            x[i] = rng.uniform(-4.0, 0.0)
        elif n.endswith("log_s"):
            x[i] = rng.uniform(math.log(math.radians(2.0)), math.log(math.radians(15.0)))
        elif n.endswith("u_lo"):
            x[i] = -rng.uniform(math.radians(5.0), math.radians(60.0))
        elif n.endswith("u_hi"):
            x[i] = rng.uniform(math.radians(5.0), math.radians(60.0))
        elif n.endswith("c2"):
            x[i] = rng.uniform(-3.0, 1.0)
        elif n in ("d1", "d2"):
            x[i] = rng.uniform(-1.0, 1.0)
    return x


def hemisphere(n, rng):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def central_difference(spec, x, wi, wr, step):
    h = step * np.maximum(1.0, np.abs(x))
    X = np.vstack([x[None] + np.diag(h), x[None] - np.diag(h)])
    f = evaluate_batch(spec, X, wi, wr)
    P = x.size
    return np.moveaxis((f[:P] - f[P:]) / (2 * h[:, None, None]), 0, -1)


@pytest.mark.parametrize("kinds", VARIANTS)
@pytest.mark.parametrize("free", [(False, False), (True, True), (True, False), (False, True)])
def test_jacobian_matches_central_differences(kinds, free):
    rng = np.random.default_rng(SEED)
    spec = PriorSpec(kinds, 2, *free)
    wi, wr = hemisphere(150, rng), hemisphere(150, rng)
    names = spec.names()
    piecewise = [i for i, n in enumerate(names) if n.endswith("psi") or n == "axis_offset"]
    for _ in range(3):
        x = random_theta(spec, rng)
        f, J = evaluate_with_jacobian(spec, x, wi, wr, cache={})
        # f is the same expression as evaluate_batch's, regrouped: rounding only
        np.testing.assert_allclose(f, evaluate_batch(spec, x[None], wi, wr)[0], rtol=1e-12)
        Jfd = central_difference(spec, x, wi, wr, FD_STEP)
        if piecewise:
            fine, coarse = (central_difference(spec, x, wi, wr, h) for h in GEOMETRY_FD_STEPS)
        for k, name in enumerate(names):
            a, b, tol = J[..., k], Jfd[..., k], ANALYTIC_RTOL
            if k in piecewise:
                smooth = np.all(np.abs(fine[..., k] - coarse[..., k]) <= 1e-4 * (np.abs(fine[..., k]) + 1e-3 * f), axis=-1)
                assert smooth.mean() >= GEOMETRY_SMOOTH_FRACTION, f"{kinds} {free} {name}: {smooth.mean():.2f} smooth"
                a, b = a[smooth], fine[smooth][..., k]
                tol = GEOMETRY_RTOL if name == "axis_offset" else ANALYTIC_RTOL
            err = np.linalg.norm(a - b)
            ref = np.linalg.norm(b) + 1e-12 * np.linalg.norm(f)
            assert err <= tol * ref, f"{kinds} {free} {name}: |ΔJ|/|J| = {err / ref:.2e}"


def test_log_jacobian_is_jacobian_over_f():
    rng = np.random.default_rng(SEED)
    spec = PriorSpec(("staple", "filament"), 1, True, True)
    x = random_theta(spec, rng)
    wi, wr = hemisphere(50, rng), hemisphere(50, rng)
    f, J = evaluate_with_jacobian(spec, x, wi, wr)
    np.testing.assert_allclose(FibrePrior(spec, x).log_jacobian(wi, wr), J / f[..., None], rtol=1e-12)


def test_residual_jacobian_matches_central_differences():
    """dr/dθ = (df/dθ)/((f + ε)σ) with per-sample σ and a floor ε that matters for some samples."""
    rng = np.random.default_rng(SEED)
    spec = PriorSpec(("filament", "filament"), 2)
    x = random_theta(spec, rng)
    wi, wr = hemisphere(100, rng), hemisphere(100, rng)
    y = evaluate_batch(spec, random_theta(spec, rng)[None], wi, wr)[0]
    d = _Data(wi, wr, y, 0.3 * np.median(y, axis=0), rng.uniform(0.5, 2.0, size=y.shape), True)
    r, J = _residual_jacobian(spec, x, d)
    np.testing.assert_allclose(r, _residuals_batch(spec, x[None], d)[0], rtol=1e-12)
    h = FD_STEP * np.maximum(1.0, np.abs(x))
    R = _residuals_batch(spec, np.vstack([x[None] + np.diag(h), x[None] - np.diag(h)]), d)
    Jfd = ((R[: x.size] - R[x.size:]) / (2 * h[:, None])).T
    # same truncation argument as ANALYTIC_RTOL (ln(f + ε) is smoother than f)
    assert np.linalg.norm(J - Jfd) <= ANALYTIC_RTOL * np.linalg.norm(Jfd)


@pytest.mark.parametrize("kinds", [("filament", "filament"), ("staple", "filament")])
def test_fit_reaches_the_finite_difference_optimum(kinds):
    """The analytic Jacobian reaches the cost the old forward-difference Jacobian reached."""
    rng = np.random.default_rng(SEED)
    spec = PriorSpec(kinds, 1)
    truth = random_theta(spec, rng)
    wi, wr = hemisphere(120, rng), hemisphere(120, rng)
    y = evaluate_batch(spec, truth[None], wi, wr)[0] * np.exp(0.05 * rng.normal(size=(120, 1)))
    eps = 1e-4 * y.max(axis=0)
    d = _Data(wi, wr, y, eps, np.ones_like(y), False)
    bounds = spec.bounds(tuple(np.sign(truth[spec.index()[n]]) if n in spec.index() else 1
                               for n in ("warp_psi", "weft_psi")))
    # a start close to the truth: from 0.05 away the staple variant's twist settles in
    # another local optimum (with either Jacobian), which is not what is tested here
    x0 = np.clip(truth + rng.normal(scale=0.005, size=truth.size), bounds[0] + 1e-6, bounds[1] - 1e-6)
    analytic = _solve(spec, x0, d, bounds, 200)

    def fd_jac(x):  # the previous implementation: forward differences of every column
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        h = np.where(x + h > bounds[1], -h, h)
        R = _residuals_batch(spec, np.vstack([x[None], x[None] + np.diag(h)]), d)
        return ((R[1:] - R[0]) / h[:, None]).T

    old = least_squares(lambda x: _residuals_batch(spec, x[None], d)[0], x0, jac=fd_jac, bounds=bounds,
                        method="trf", x_scale="jac", max_nfev=200, ftol=1e-8, xtol=1e-8, gtol=1e-8,
                        tr_solver="lsmr")
    # Both stop on ftol = 1e-8 (relative change of the cost), from the same start into
    # the same basin: their costs agree to a few ftol; 1e-4 is loose for that and far
    # tighter than the gap between distinct local optima (≳ 10 % here).
    truth_cost = 0.5 * np.sum(_residuals_batch(spec, truth[None], d) ** 2)
    assert abs(analytic.cost - old.cost) <= 1e-4 * old.cost
    # and it is the optimum near the truth: 5 % log noise on 120 samples, cost ≤ the truth's
    assert analytic.cost <= truth_cost
