"""The kes BRDF evaluation of kesbrdf 0.1.0, kept verbatim (math only) as the regression
reference for the optimised :mod:`kesbrdf.models.brdf` (tests/test_brdf.py).  Not imported by
the package."""

import numpy as np

AZIMUTH_EPS = 1e-12
PAPER_MIN_SIN_BETA = 1e-6


def _azimuth(v, fallback):
    small = np.hypot(v[..., 0], v[..., 1]) < AZIMUTH_EPS
    x = np.where(small, fallback[..., 0], v[..., 0])
    y = np.where(small, fallback[..., 1], v[..., 1])
    return np.mod(np.arctan2(y, x), 2 * np.pi)


def to_phi_gamma(wi, wr, mapping="deviation"):
    wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
    plane = wr - wi
    if mapping == "deviation":
        m = wi * np.array([-1.0, -1.0, 1.0])
        cross = np.linalg.norm(np.cross(wr, m), axis=-1)
        gamma = np.arctan2(cross, np.sum(wr * m, axis=-1))
        phi = _azimuth(wi + wr, plane)
    else:
        h = wi + wr
        gamma = 2.0 * np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
        phi = _azimuth(h, plane)
    return phi, gamma


def paper_phi_gamma(theta_i, phi_i, theta_r, phi_r):
    phi = np.mod(np.pi / 2 - (phi_i + phi_r), 2 * np.pi)
    gamma = theta_r - theta_i
    half = 0.5 * np.sqrt(np.sin(phi_r - phi_i - np.pi) ** 2 + np.cos(theta_r) ** 2)
    beta = 2.0 * np.arcsin(np.clip(half, 0.0, 1.0))
    return phi, gamma, np.maximum(np.sin(beta), PAPER_MIN_SIN_BETA)


def lookup(model, phi, gamma):
    phi, gamma = np.broadcast_arrays(np.asarray(phi, float), np.asarray(gamma, float))
    n_phi = model.phi_grid.size
    n_gamma = model.gamma_grid.size
    u = np.mod(phi, 2 * np.pi) * (n_phi / (2 * np.pi))
    dgamma = model.gamma_grid[1] - model.gamma_grid[0]
    v = np.clip(gamma, 0.0, model.gamma_grid[-1]) / dgamma
    nan = ~(np.isfinite(u) & np.isfinite(v))
    u = np.where(nan, 0.0, u)
    v = np.where(nan, 0.0, v)
    i0 = np.floor(u).astype(np.intp)
    fu = u - i0
    i0 %= n_phi
    i1 = (i0 + 1) % n_phi
    j0 = np.minimum(np.floor(v).astype(np.intp), n_gamma - 1)
    fv = v - j0
    j1 = np.minimum(j0 + 1, n_gamma - 1)
    T = model.table
    fu = fu[..., None]
    fv = fv[..., None]
    q = (T[i0, j0] * (1 - fu) + T[i1, j0] * fu) * (1 - fv) + (T[i0, j1] * (1 - fu) + T[i1, j1] * fu) * fv
    return np.where(nan[..., None], np.nan, q)


def evaluate(model, wi, wr, mapping="deviation"):
    wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
    cos_theta_i = wi[..., 2]
    cos_theta_r = wr[..., 2]
    above = (cos_theta_i > 0) & (cos_theta_r > 0)
    nan_in = np.isnan(cos_theta_i) | np.isnan(cos_theta_r)
    with np.errstate(invalid="ignore", divide="ignore"):
        norm = np.sqrt(np.where(above, cos_theta_i * cos_theta_r, 1.0))
        if mapping == "paper":
            theta_i = np.arccos(np.clip(cos_theta_i, -1, 1))
            theta_r = np.arccos(np.clip(cos_theta_r, -1, 1))
            phi_i = np.arctan2(wi[..., 1], wi[..., 0])
            phi_r = np.arctan2(wr[..., 1], wr[..., 0])
            phi, gamma, sin_beta = paper_phi_gamma(theta_i, phi_i, theta_r, phi_r)
            phi = np.where(gamma < 0, phi + np.pi, phi)
            rho = lookup(model, phi, np.abs(gamma)) + model.body * np.sqrt(np.clip(np.cos(gamma), 0, None) / 2)[..., None]
            f = rho / (norm * sin_beta)[..., None]
        else:
            phi, gamma = to_phi_gamma(wi, wr, mapping)
            f = model.body + lookup(model, phi, gamma) / norm[..., None]
    f = np.where(above[..., None], f, 0.0)
    return np.where(nan_in[..., None], np.nan, f)
