"""Bounded trust-region least squares on a small dense Jacobian, without operator overhead.

:func:`least_squares_lsmr` runs the algorithm of ``scipy.optimize.least_squares(fun, x0,
jac=jac, bounds=(lb, ub), method="trf", x_scale="jac", tr_solver="lsmr")`` (linear loss):
the trust-region reflective method of Branch, Coleman & Li (1999) with the Coleman–Li
scaling, whose step is the 2-D subspace spanned by the scaled gradient and a regularised
Gauss–Newton direction from LSMR (Fong & Saunders 2011).  The arithmetic is the same,
operation for operation, as SciPy's (``scipy/optimize/_lsq/trf.py`` and ``common.py``,
``scipy/sparse/linalg/_isolve/lsmr.py``, SciPy 1.17; BSD-3-Clause, (c) the SciPy
developers): the fits are bit-identical to ``least_squares`` there (tests/test_trf_dense.py).

Why a copy: SciPy wraps the dense Jacobian in three nested ``LinearOperator`` layers, so
each of LSMR's products costs tens of microseconds of Python on a Jacobian of a few
hundred rows; the fibre prior's fits (:func:`kesbrdf.models.fibre_physics.fit_prior`,
about 20 solves per fit and five fits in ``kesbrdf fit``'s leave-one-orientation-out
comparison) spent about 45 % of their time there (benchmarks/bench_default_fit.py).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from scipy.linalg import qr
from scipy.linalg.lapack import dpotrf as _dpotrf, dpotrs as _dpotrs

__all__ = ["least_squares_lsmr"]

_EPS = np.finfo(float).eps


def _norm(x):
    """numpy.linalg.norm of a 1-D real vector (the same sqrt(x·x))."""
    return np.sqrt(x.dot(x))


class _ScaledJacobian:
    """J diag(d) as the products SciPy's ``right_multiplied_operator(aslinearoperator(J), d)`` forms."""

    def __init__(self, J, d):
        self.J, self.d = J, d
        self.m, self.n = J.shape

    def matvec(self, x):  # MatrixLinearOperator.matvec: a (n, 1) product, reshaped
        return self.J.dot((x * self.d).reshape(-1, 1)).reshape(self.m)

    def rmatvec(self, x):  # d * (J^T conj) x, again through a (m, 1) column
        return self.d * self.J.T.dot(x.reshape(-1, 1)).reshape(self.n)

    def matmat(self, X):
        return self.J.dot(X * self.d[:, np.newaxis])

    def dot(self, x):
        return self.matvec(x) if x.ndim == 1 else self.matmat(x)


# -- SciPy's helpers (scipy/optimize/_lsq/common.py), dense case only ----------------------

def _intersect_trust_region(x, s, Delta):
    a = np.dot(s, s)
    if a == 0:
        raise ValueError("`s` is zero.")
    b = np.dot(x, s)
    c = np.dot(x, x) - Delta**2
    if c > 0:
        raise ValueError("`x` is not within the trust region.")
    d = np.sqrt(b * b - a * c)
    q = -(b + math.copysign(d, b))
    t1 = q / a
    t2 = c / q
    if t1 < t2:
        return t1, t2
    return t2, t1


def _solve_trust_region_2d(B, g, Delta):
    try:
        R, lower = _cho_factor(B)
        p = -_cho_solve((R, lower), g)
        if np.dot(p, p) <= Delta**2:
            return p, True
    except np.linalg.LinAlgError:
        pass
    a = B[0, 0] * Delta**2
    b = B[0, 1] * Delta**2
    c = B[1, 1] * Delta**2
    d = g[0] * Delta
    f = g[1] * Delta
    coeffs = np.array([-b + d, 2 * (a - c + f), 6 * b, 2 * (-a + c + f), -b - d])
    t = np.roots(coeffs)  # Can handle leading zeros.
    t = np.real(t[np.isreal(t)])
    p = Delta * np.vstack((2 * t / (1 + t**2), (1 - t**2) / (1 + t**2)))
    value = 0.5 * np.sum(p * B.dot(p), axis=0) + np.dot(g, p)
    i = np.argmin(value)
    p = p[:, i]
    return p, False


def _update_tr_radius(Delta, actual_reduction, predicted_reduction, step_norm, bound_hit):
    if predicted_reduction > 0:
        ratio = actual_reduction / predicted_reduction
    elif predicted_reduction == actual_reduction == 0:
        ratio = 1
    else:
        ratio = 0
    if ratio < 0.25:
        Delta = 0.25 * step_norm
    elif ratio > 0.75 and bound_hit:
        Delta *= 2.0
    return Delta, ratio


def _build_quadratic_1d(J, g, s, diag=None, s0=None):
    v = J.dot(s)
    a = np.dot(v, v)
    if diag is not None:
        a += np.dot(s * diag, s)
    a *= 0.5
    b = np.dot(g, s)
    if s0 is not None:
        u = J.dot(s0)
        b += np.dot(u, v)
        c = 0.5 * np.dot(u, u) + np.dot(g, s0)
        if diag is not None:
            b += np.dot(s0 * diag, s)
            c += 0.5 * np.dot(s0 * diag, s0)
        return a, b, c
    return a, b


def _minimize_quadratic_1d(a, b, lb, ub, c=0):
    t = [lb, ub]
    if a != 0:
        extremum = -0.5 * b / a
        if lb < extremum < ub:
            t.append(extremum)
    t = np.asarray(t)
    y = t * (a * t + b) + c
    min_index = np.argmin(y)
    return t[min_index], y[min_index]


def _evaluate_quadratic(J, g, s, diag=None):
    Js = J.dot(s)
    q = np.dot(Js, Js)
    if diag is not None:
        q += np.dot(s * diag, s)
    l = np.dot(s, g)  # noqa: E741
    return 0.5 * q + l


def _in_bounds(x, lb, ub):
    return np.all((x >= lb) & (x <= ub))


def _step_size_to_bound(x, s, lb, ub):
    non_zero = np.nonzero(s)
    s_non_zero = s[non_zero]
    steps = np.empty_like(x)
    steps.fill(np.inf)
    with np.errstate(over="ignore"):
        steps[non_zero] = np.maximum((lb - x)[non_zero] / s_non_zero, (ub - x)[non_zero] / s_non_zero)
    min_step = np.min(steps)
    return min_step, np.equal(steps, min_step) * np.sign(s).astype(int)


def _find_active_constraints(x, lb, ub, rtol=1e-10):
    active = np.zeros_like(x, dtype=int)
    if rtol == 0:
        active[x <= lb] = -1
        active[x >= ub] = 1
        return active
    lower_dist = x - lb
    upper_dist = ub - x
    lower_threshold = rtol * np.maximum(1, np.abs(lb))
    upper_threshold = rtol * np.maximum(1, np.abs(ub))
    lower_active = np.isfinite(lb) & (lower_dist <= np.minimum(upper_dist, lower_threshold))
    active[lower_active] = -1
    upper_active = np.isfinite(ub) & (upper_dist <= np.minimum(lower_dist, upper_threshold))
    active[upper_active] = 1
    return active


def _make_strictly_feasible(x, lb, ub, rstep=1e-10):
    x_new = x.copy()
    active = _find_active_constraints(x, lb, ub, rstep)
    lower_mask = np.equal(active, -1)
    upper_mask = np.equal(active, 1)
    if rstep == 0:
        x_new[lower_mask] = np.nextafter(lb[lower_mask], ub[lower_mask])
        x_new[upper_mask] = np.nextafter(ub[upper_mask], lb[upper_mask])
    else:
        x_new[lower_mask] = lb[lower_mask] + rstep * np.maximum(1, np.abs(lb[lower_mask]))
        x_new[upper_mask] = ub[upper_mask] - rstep * np.maximum(1, np.abs(ub[upper_mask]))
    tight_bounds = (x_new < lb) | (x_new > ub)
    x_new[tight_bounds] = 0.5 * (lb[tight_bounds] + ub[tight_bounds])
    return x_new


def _cl_scaling_vector(x, g, lb, ub):
    v = np.ones_like(x)
    dv = np.zeros_like(x)
    mask = (g < 0) & np.isfinite(ub)
    v[mask] = ub[mask] - x[mask]
    dv[mask] = -1
    mask = (g > 0) & np.isfinite(lb)
    v[mask] = x[mask] - lb[mask]
    dv[mask] = 1
    return v, dv


def _compute_jac_scale(J, scale_inv_old=None):
    scale_inv = np.sum(J**2, axis=0) ** 0.5
    if scale_inv_old is None:
        scale_inv[scale_inv == 0] = 1
    else:
        scale_inv = np.maximum(scale_inv, scale_inv_old)
    return 1 / scale_inv, scale_inv


def _check_termination(dF, F, dx_norm, x_norm, ratio, ftol, xtol):
    ftol_satisfied = dF < ftol * F and ratio > 0.25
    xtol_satisfied = dx_norm < xtol * (xtol + x_norm)
    if ftol_satisfied and xtol_satisfied:
        return 4
    if ftol_satisfied:
        return 2
    if xtol_satisfied:
        return 3
    return None


def _cho_factor(B):
    """scipy.linalg.cho_factor(B) (upper): the same LAPACK potrf call without the wrapper's layers."""
    if not np.all(np.isfinite(B)):
        raise ValueError("array must not contain infs or NaNs")
    c, info = _dpotrf(B, lower=False, overwrite_a=False, clean=False)
    if info > 0:
        raise np.linalg.LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f"illegal value in argument {-info} of potrf")
    return c, False


def _cho_solve(c_and_lower, g):
    """scipy.linalg.cho_solve: LAPACK potrs on the factor of :func:`_cho_factor`."""
    c, lower = c_and_lower
    if not np.all(np.isfinite(g)):
        raise ValueError("array must not contain infs or NaNs")
    x, info = _dpotrs(c, g, lower=lower, overwrite_b=False)
    if info != 0:
        raise ValueError(f"illegal value in argument {-info} of potrs")
    return x


# -- LSMR (scipy/sparse/linalg/_isolve/lsmr.py) on [J diag(d); diag(reg)] -----------------

def _sym_ortho(a, b, sign=np.sign):
    if b == 0:
        return sign(a), 0, abs(a)
    elif a == 0:
        return 0, sign(b), abs(b)
    elif abs(b) > abs(a):
        tau = a / b
        s = sign(b) / math.sqrt(1 + tau * tau)
        c = s * tau
        r = b / s
    else:
        tau = b / a
        c = sign(a) / math.sqrt(1 + tau * tau)
        s = c * tau
        r = a / c
    return c, s, r


def _float_sign(a):
    """np.sign of a finite float as a Python float (a NaN leaves the fast path: :func:`_lsmr`)."""
    if a != a:
        raise _LeaveFastPath
    return 1.0 if a > 0 else (-1.0 if a < 0 else 0.0)


def _float_norm(x):
    """:func:`_norm` as a Python float (the same correctly rounded sqrt of the same x·x)."""
    return math.sqrt(float(x.dot(x)))


class _LeaveFastPath(Exception):
    pass


def _lsmr(Jh, reg, b, atol=1e-6, btol=1e-6, conlim=1e8):
    """x minimising |[Jh; diag(reg)] x − b| (LSMR, damp 0, x0 = 0, maxiter = n).

    SciPy's recurrences run on NumPy float64 scalars; the same IEEE operations on Python
    floats give the same bits at a third of the cost.  Where the two differ (a division by
    zero, an overflow or a NaN: NumPy gives inf/NaN, Python raises) the solve is redone on
    NumPy scalars, as SciPy does it.
    """
    try:
        return _lsmr_run(Jh, reg, b, atol, btol, conlim, _float_norm, _float_sign)
    except (ZeroDivisionError, OverflowError, ValueError, _LeaveFastPath):
        return _lsmr_run(Jh, reg, b, atol, btol, conlim, _norm, np.sign)


def _lsmr_run(Jh, reg, b, atol, btol, conlim, norm, sign):
    """The LSMR iterations of :func:`_lsmr` with the given norm and sign (their scalar type)."""
    m, n = Jh.m, Jh.n

    def matvec(x):  # regularized_lsq_operator's matvec: [Jh x; reg x]
        out = np.empty(m + n)
        out[:m] = Jh.matvec(x)
        np.multiply(reg, x, out=out[m:])
        return out

    def rmatvec(x):
        return Jh.rmatvec(x[:m]) + reg * x[m:]

    maxiter = min(m + n, n)
    u = b
    normb = norm(b)
    x = np.zeros(n, float)
    beta = normb
    if beta > 0:
        u = (1 / beta) * u
        v = rmatvec(u)
        alpha = norm(v)
    else:
        v = np.zeros(n, float)
        alpha = 0
    if alpha > 0:
        v = (1 / alpha) * v
    itn = 0
    zetabar = alpha * beta
    alphabar = alpha
    rho = 1
    rhobar = 1
    cbar = 1
    sbar = 0
    h = v.copy()
    hbar = np.zeros(n, float)
    betadd = beta
    betad = 0
    rhodold = 1
    tautildeold = 0
    thetatilde = 0
    zeta = 0
    d = 0
    normA2 = alpha * alpha
    maxrbar = 0
    minrbar = 1e100
    normA = math.sqrt(normA2)
    condA = 1
    normx = 0
    istop = 0
    ctol = 1 / conlim if conlim > 0 else 0
    normr = beta
    normar = alpha * beta
    if normar == 0:
        return x
    if normb == 0:
        x[()] = 0
        return x
    while itn < maxiter:
        itn = itn + 1
        u *= -alpha
        u += matvec(v)
        beta = norm(u)
        if beta > 0:
            u *= 1 / beta
            v *= -beta
            v += rmatvec(u)
            alpha = norm(v)
            if alpha > 0:
                v *= 1 / alpha
        chat, shat, alphahat = _sym_ortho(alphabar, 0.0, sign)
        rhoold = rho
        c, s, rho = _sym_ortho(alphahat, beta, sign)
        thetanew = s * alpha
        alphabar = c * alpha
        rhobarold = rhobar
        zetaold = zeta
        thetabar = sbar * rho
        rhotemp = cbar * rho
        cbar, sbar, rhobar = _sym_ortho(cbar * rho, thetanew, sign)
        zeta = cbar * zetabar
        zetabar = -sbar * zetabar
        hbar *= -(thetabar * rho / (rhoold * rhobarold))
        hbar += h
        x += (zeta / (rho * rhobar)) * hbar
        h *= -(thetanew / rho)
        h += v
        betaacute = chat * betadd
        betacheck = -shat * betadd
        betahat = c * betaacute
        betadd = -s * betaacute
        thetatildeold = thetatilde
        ctildeold, stildeold, rhotildeold = _sym_ortho(rhodold, thetabar, sign)
        thetatilde = stildeold * rhobar
        rhodold = ctildeold * rhobar
        betad = -stildeold * betad + ctildeold * betahat
        tautildeold = (zetaold - thetatildeold * tautildeold) / rhotildeold
        taud = (zeta - thetatilde * tautildeold) / rhodold
        d = d + betacheck * betacheck
        normr = math.sqrt(d + (betad - taud) ** 2 + betadd * betadd)
        normA2 = normA2 + beta * beta
        normA = math.sqrt(normA2)
        normA2 = normA2 + alpha * alpha
        maxrbar = max(maxrbar, rhobarold)
        if itn > 1:
            minrbar = min(minrbar, rhobarold)
        condA = max(maxrbar, rhotemp) / min(minrbar, rhotemp)
        normar = abs(zetabar)
        normx = norm(x)
        test1 = normr / normb
        if (normA * normr) != 0:
            test2 = normar / (normA * normr)
        else:
            test2 = math.inf
        test3 = 1 / condA
        t1 = test1 / (1 + normA * normx / normb)
        rtol = btol + atol * normA * normx / normb
        if itn >= maxiter:
            istop = 7
        if 1 + test3 <= 1:
            istop = 6
        if 1 + test2 <= 1:
            istop = 5
        if 1 + t1 <= 1:
            istop = 4
        if test3 <= ctol:
            istop = 3
        if test2 <= atol:
            istop = 2
        if test1 <= rtol:
            istop = 1
        if istop > 0:
            break
    return x


# -- the trust-region reflective loop (scipy/optimize/_lsq/trf.py: trf_bounds) ---------------

def _select_step(x, J_h, diag_h, g_h, p, p_h, d, Delta, lb, ub, theta):
    if _in_bounds(x + p, lb, ub):
        p_value = _evaluate_quadratic(J_h, g_h, p_h, diag=diag_h)
        return p, p_h, -p_value
    p_stride, hits = _step_size_to_bound(x, p, lb, ub)
    r_h = np.copy(p_h)
    r_h[hits.astype(bool)] *= -1
    r = d * r_h
    p *= p_stride
    p_h *= p_stride
    x_on_bound = x + p
    _, to_tr = _intersect_trust_region(p_h, r_h, Delta)
    to_bound, _ = _step_size_to_bound(x_on_bound, r, lb, ub)
    r_stride = min(to_bound, to_tr)
    if r_stride > 0:
        r_stride_l = (1 - theta) * p_stride / r_stride
        if r_stride == to_bound:
            r_stride_u = theta * to_bound
        else:
            r_stride_u = to_tr
    else:
        r_stride_l = 0
        r_stride_u = -1
    if r_stride_l <= r_stride_u:
        a, b, c = _build_quadratic_1d(J_h, g_h, r_h, s0=p_h, diag=diag_h)
        r_stride, r_value = _minimize_quadratic_1d(a, b, r_stride_l, r_stride_u, c=c)
        r_h *= r_stride
        r_h += p_h
        r = r_h * d
    else:
        r_value = np.inf
    p *= theta
    p_h *= theta
    p_value = _evaluate_quadratic(J_h, g_h, p_h, diag=diag_h)
    ag_h = -g_h
    ag = d * ag_h
    to_tr = Delta / _norm(ag_h)
    to_bound, _ = _step_size_to_bound(x, ag, lb, ub)
    if to_bound < to_tr:
        ag_stride = theta * to_bound
    else:
        ag_stride = to_tr
    a, b = _build_quadratic_1d(J_h, g_h, ag_h, diag=diag_h)
    ag_stride, ag_value = _minimize_quadratic_1d(a, b, 0, ag_stride)
    ag_h *= ag_stride
    ag *= ag_stride
    if p_value < r_value and p_value < ag_value:
        return p, p_h, -p_value
    elif r_value < p_value and r_value < ag_value:
        return r, r_h, -r_value
    return ag, ag_h, -ag_value


def least_squares_lsmr(fun, x0, jac, bounds, max_nfev, ftol=1e-8, xtol=1e-8, gtol=1e-8):
    """Minimise ½|fun(x)|² for lb ≤ x ≤ ub (module docstring).

    ``fun(x)`` returns the residuals (m,), ``jac(x)`` their dense Jacobian (m, n); ``x0``
    must lie within the finite ``bounds``.  Returns a namespace with ``x``, ``cost``,
    ``fun``, ``jac``, ``grad``, ``optimality``, ``active_mask``, ``nfev``, ``njev``,
    ``status`` and ``success`` as ``scipy.optimize.least_squares`` does.
    """
    lb, ub = (np.asarray(b, float) for b in bounds)
    x0 = np.atleast_1d(x0).astype(float)
    if lb.shape != x0.shape or ub.shape != x0.shape or np.any(lb >= ub):
        raise ValueError(f"expected lower < upper bounds of x0's shape {x0.shape}, got {lb.shape} and {ub.shape}")
    if not _in_bounds(x0, lb, ub):
        raise ValueError("Initial guess is outside of provided bounds")
    x0 = _make_strictly_feasible(x0, lb, ub)
    for tol in (ftol, xtol, gtol):
        if tol < _EPS:
            raise ValueError(f"tolerances must be at least {_EPS}, got {tol}")
    f0 = np.atleast_1d(fun(x0))
    if f0.ndim != 1:
        raise ValueError(f"`fun` must return at most 1-d array_like. f0.shape: {f0.shape}")
    if not np.all(np.isfinite(f0)):
        raise ValueError("Residuals are not finite in the initial point.")
    J0 = np.atleast_2d(jac(x0))
    if J0.shape != (f0.size, x0.size):
        raise ValueError(f"The return value of `jac` has wrong shape: expected {(f0.size, x0.size)}, actual {J0.shape}.")

    x = x0.copy()
    f = f0
    f_true = f.copy()
    nfev = 1
    J = J0
    njev = 1
    m, n = J.shape
    cost = 0.5 * np.dot(f, f)
    g = J.T.dot(f)
    scale, scale_inv = _compute_jac_scale(J)
    v, dv = _cl_scaling_vector(x, g, lb, ub)
    v[dv != 0] *= scale_inv[dv != 0]
    Delta = _norm(x0 * scale_inv / v**0.5)
    if Delta == 0:
        Delta = 1.0
    g_norm = np.linalg.norm(g * v, ord=np.inf)
    f_augmented = np.zeros(m + n)
    reg_term = 0.0
    termination_status = None
    while True:
        v, dv = _cl_scaling_vector(x, g, lb, ub)
        g_norm = np.linalg.norm(g * v, ord=np.inf)
        if g_norm < gtol:
            termination_status = 1
        if termination_status is not None or nfev == max_nfev:
            break
        v[dv != 0] *= scale_inv[dv != 0]
        d = v**0.5 * scale
        diag_h = g * dv * scale
        g_h = d * g
        f_augmented[:m] = f
        J_h = _ScaledJacobian(J, d)
        a, b = _build_quadratic_1d(J_h, g_h, -g_h, diag=diag_h)
        to_tr = Delta / _norm(g_h)
        ag_value = _minimize_quadratic_1d(a, b, 0, to_tr)[1]
        reg_term = -ag_value / Delta**2
        gn_h = _lsmr(J_h, (diag_h + reg_term) ** 0.5, f_augmented)
        S = np.vstack((g_h, gn_h)).T
        S, _ = qr(S, mode="economic")
        JS = J_h.dot(S)
        B_S = np.dot(JS.T, JS) + np.dot(S.T * diag_h, S)
        g_S = S.T.dot(g_h)
        theta = max(0.995, 1 - g_norm)
        actual_reduction = -1
        while actual_reduction <= 0 and nfev < max_nfev:
            p_S, _ = _solve_trust_region_2d(B_S, g_S, Delta)
            p_h = S.dot(p_S)
            p = d * p_h
            step, step_h, predicted_reduction = _select_step(x, J_h, diag_h, g_h, p, p_h, d, Delta, lb, ub, theta)
            x_new = _make_strictly_feasible(x + step, lb, ub, rstep=0)
            f_new = np.atleast_1d(fun(x_new))
            nfev += 1
            step_h_norm = _norm(step_h)
            if not np.all(np.isfinite(f_new)):
                Delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * np.dot(f_new, f_new)
            actual_reduction = cost - cost_new
            Delta_new, ratio = _update_tr_radius(Delta, actual_reduction, predicted_reduction,
                                                 step_h_norm, step_h_norm > 0.95 * Delta)
            step_norm = _norm(step)
            termination_status = _check_termination(actual_reduction, cost, step_norm, _norm(x), ratio, ftol, xtol)
            if termination_status is not None:
                break
            Delta = Delta_new
        if actual_reduction > 0:
            x = x_new
            f = f_new
            f_true = f.copy()
            cost = cost_new
            J = np.atleast_2d(jac(x))
            njev += 1
            g = J.T.dot(f)
            scale, scale_inv = _compute_jac_scale(J, scale_inv)
    if termination_status is None:
        termination_status = 0
    return SimpleNamespace(x=x, cost=cost, fun=f_true, jac=J, grad=g, optimality=g_norm,
                           active_mask=_find_active_constraints(x, lb, ub, rtol=xtol), nfev=nfev, njev=njev,
                           status=termination_status, success=termination_status > 0)
