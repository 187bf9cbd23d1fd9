"""kesbrdf.models.trf_dense replays scipy's least_squares(trf, lsmr, x_scale='jac') bit for bit.

The fibre prior's fits, and with them the kind ``kesbrdf fit`` chooses, must not change
when its solver drops SciPy's operator layers: every comparison here is exact equality
(no tolerance), on problems whose bounds are active, whose starts sit on a bound, and on
the prior's own residuals.
"""

from __future__ import annotations

import numpy as np
import pytest

scipy_optimize = pytest.importorskip("scipy.optimize")

from kesbrdf.models.trf_dense import least_squares_lsmr  # noqa: E402


def _scipy(fun, x0, jac, bounds, max_nfev):
    return scipy_optimize.least_squares(fun, x0, jac=jac, bounds=bounds, method="trf", x_scale="jac",
                                        max_nfev=max_nfev, ftol=1e-8, xtol=1e-8, gtol=1e-8, tr_solver="lsmr")


def _assert_same(a, b):
    assert np.array_equal(a.x, b.x)
    assert a.cost == b.cost
    assert np.array_equal(a.fun, b.fun)
    assert a.nfev == b.nfev and a.njev == b.njev and a.status == b.status
    assert np.array_equal(a.active_mask, b.active_mask)


def _exp_problem(seed):
    """Sum of two decaying exponentials with noise: 4 parameters, bounds that bind."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 4, 60)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 * np.exp(-0.2 * t) + 0.01 * rng.normal(size=t.size)

    def fun(p):
        return p[0] * np.exp(-p[1] * t) + p[2] * np.exp(-p[3] * t) - y

    def jac(p):
        e1, e3 = np.exp(-p[1] * t), np.exp(-p[3] * t)
        return np.column_stack([e1, -p[0] * t * e1, e3, -p[2] * t * e3])

    return fun, jac


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("max_nfev", [5, 40, 200])
def test_matches_scipy_on_exponentials(seed, max_nfev):
    fun, jac = _exp_problem(seed)
    rng = np.random.default_rng(100 + seed)
    lo = np.array([0.0, 0.0, 0.0, 0.0])
    hi = np.array([1.5, 3.0, 1.0, 0.15])  # the true 2.0 and 0.2 lie outside: bounds bind
    x0 = rng.uniform(lo, hi)
    x0[seed % 4] = lo[seed % 4]  # a start on a bound (made strictly feasible by both)
    _assert_same(least_squares_lsmr(fun, x0, jac, (lo, hi), max_nfev), _scipy(fun, x0, jac, (lo, hi), max_nfev))


def test_matches_scipy_on_prior_residuals():
    """The fibre prior's residuals on a virtual paper-protocol satin, staple/staple (the ψ columns)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models import fibre_physics as fp
    from kesbrdf.references.sadeghi2013 import Sadeghi2013

    m = measure(Sadeghi2013("satin"), protocol="paper")
    d = fp._prepare(m)
    spec = fp.PriorSpec(("staple", "staple"), m.values.shape[1])
    bounds = spec.bounds((1, -1))
    x0 = fp._scale_ks_start(spec, fp._start(spec, d, 20.0, 0.0, (20.0, -20.0)), d)
    x0 = np.clip(x0, bounds[0] + 1e-9, bounds[1] - 1e-9)

    def fun(x):
        return fp._residuals_batch(spec, x[None], d)[0]

    def jac(x):
        return fp._residual_jacobian(spec, x, d)[1]

    _assert_same(least_squares_lsmr(fun, x0, jac, bounds, 25), _scipy(fun, x0, jac, bounds, 25))


def test_rejects_a_start_outside_the_bounds():
    fun, jac = _exp_problem(0)
    with pytest.raises(ValueError, match="outside"):
        least_squares_lsmr(fun, np.array([2.0, 1.0, 0.5, 0.1]), jac, (np.zeros(4), np.ones(4)), 10)


def test_lsmr_float_scalars_match_numpy_scalars():
    """LSMR's recurrences on Python floats give SciPy's float64-scalar bits (and NaN takes the NumPy path)."""
    from kesbrdf.models import trf_dense as td

    rng = np.random.default_rng(7)
    for k in range(20):
        m, n = 30 + k, 5 + k % 7
        Jh = td._ScaledJacobian(rng.normal(size=(m, n)) * np.exp(rng.normal(size=n)), rng.uniform(0.1, 2.0, n))
        reg = rng.uniform(0.0, 1.0, n) * (k % 3 != 0)  # some without regularisation
        b = np.concatenate([rng.normal(size=m), np.zeros(n)])
        fast = td._lsmr_run(Jh, reg, b, 1e-6, 1e-6, 1e8, td._float_norm, td._float_sign)
        slow = td._lsmr_run(Jh, reg, b, 1e-6, 1e-6, 1e8, td._norm, np.sign)
        assert np.array_equal(fast, slow)
    with pytest.raises(td._LeaveFastPath):
        td._float_sign(float("nan"))
