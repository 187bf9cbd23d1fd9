r"""From the model ρ(φ, γ) to a BRDF f_r(wi, wr) (paper eq. 3–4, DESIGN §4).

Three mappings from a pair of directions to (φ, γ), selected by name through
:func:`validate_mapping`:

``deviation`` (default)
    γ = angle between wr and the mirror image of wi, m = (−x, −y, z);
    φ = azimuth of (wi + wr) projected on the fabric plane.  Fig. 5 read literally: a
    lobe around the mirror direction whose width depends on the deviation's azimuth.
``halfvector``
    γ = 2 θ_h and φ = φ_h of the half vector (Ward- and microfacet-like).
``paper``
    Eq. 3–4 taken literally (see :func:`paper_phi_gamma`).

For the first two,

.. math:: f_r(\omega_i, \omega_r) = c + \frac{q(\phi, \gamma)}{\sqrt{\cos\theta_i\cos\theta_r}}

with q read from the table by bilinear interpolation (periodic in φ, γ clamped to the
measured range).  Both are reciprocal by construction and return every in-plane
input sample exactly.  At γ = 0, where the deviation has no azimuth, φ is the
azimuth of the plane of incidence, (wr − wi) projected (DESIGN §4).

Directions at or below the horizon give 0; NaN in gives NaN out.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import KesbrdfError

__all__ = [
    "MAPPINGS",
    "validate_mapping",
    "to_phi_gamma",
    "paper_phi_gamma",
    "lookup",
    "evaluate",
    "PAPER_MIN_SIN_BETA",
]

MAPPINGS = ("deviation", "halfvector", "paper")

#: Projected lengths below this count as zero when taking an azimuth.
AZIMUTH_EPS = 1e-12
#: eq. 3 divides by sin β; it is clamped here (the printed equation is singular).
PAPER_MIN_SIN_BETA = 1e-6


def validate_mapping(mapping: str) -> str:
    """Return ``mapping`` if it is a known name, else raise with the valid names."""
    if mapping not in MAPPINGS:
        raise KesbrdfError(f"unknown mapping {mapping!r}; expected one of {', '.join(MAPPINGS)}")
    return mapping


def _azimuth(v, fallback):
    """Azimuth of ``v`` projected on the plane, or of ``fallback`` where that is ~0."""
    small = np.hypot(v[..., 0], v[..., 1]) < AZIMUTH_EPS
    x = np.where(small, fallback[..., 0], v[..., 0])
    y = np.where(small, fallback[..., 1], v[..., 1])
    return np.mod(np.arctan2(y, x), 2 * np.pi)


def to_phi_gamma(wi, wr, mapping: str = "deviation"):
    """(φ, γ) of direction pairs for the ``deviation`` or ``halfvector`` mapping.

    Parameters
    ----------
    wi, wr : array_like, shape (..., 3)
        Unit vectors toward the light and the viewer, fabric frame.

    Returns
    -------
    phi : ndarray
        Deviation azimuth in [0, 2π).
    gamma : ndarray
        Deviation from the mirror direction, [0, π].

    >>> wi = np.array([-np.sin(0.5), 0, np.cos(0.5)]); wr = np.array([np.sin(0.7), 0, np.cos(0.7)])
    >>> [round(float(v), 12) for v in to_phi_gamma(wi, wr)]
    [0.0, 0.2]
    """
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    wi, wr = np.broadcast_arrays(wi, wr)
    plane = wr - wi
    if mapping == "deviation":
        m = wi * np.array([-1.0, -1.0, 1.0])
        cross = np.linalg.norm(np.cross(wr, m), axis=-1)
        gamma = np.arctan2(cross, np.sum(wr * m, axis=-1))
        phi = _azimuth(wi + wr, plane)
    elif mapping == "halfvector":
        h = wi + wr
        gamma = 2.0 * np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
        phi = _azimuth(h, plane)
    else:
        raise KesbrdfError(
            f"to_phi_gamma: expected mapping 'deviation' or 'halfvector', got {mapping!r}"
        )
    return phi, gamma


def paper_phi_gamma(theta_i, phi_i, theta_r, phi_r):
    r"""Eq. 3–4 read literally: (φ, signed γ) and sin β.

    .. math::

        \phi = \frac{\pi}{2} - (\phi_i + \phi_r),\quad \gamma = \theta_r - \theta_i,\quad
        \sin\frac{\beta}{2} = \frac12\sqrt{\sin^2(\phi_r - \phi_i - \pi) + \cos^2\theta_r}
        \tag{3–4}

    Kept to reproduce the paper, not recommended: the printed formula is not
    reciprocal (θ_r and θ_i enter eq. 4 differently), is singular where sin β → 0
    (sin β is clamped at :data:`PAPER_MIN_SIN_BETA`) and at grazing angles
    (cos θ → 0), and its φ depends on the sum of the azimuths, so the highlight it
    predicts is not a lobe around the mirror direction once the fabric is rotated.
    Signed γ < 0 reads the table at azimuth φ + π (DESIGN §4).
    """
    phi = np.mod(np.pi / 2 - (phi_i + phi_r), 2 * np.pi)
    gamma = theta_r - theta_i
    half = 0.5 * np.sqrt(np.sin(phi_r - phi_i - np.pi) ** 2 + np.cos(theta_r) ** 2)
    beta = 2.0 * np.arcsin(np.clip(half, 0.0, 1.0))
    return phi, gamma, np.maximum(np.sin(beta), PAPER_MIN_SIN_BETA)


def lookup(model, phi, gamma) -> np.ndarray:
    """Bilinear lookup of the lobe table q at (φ, γ) (docs/formats.md, step 2).

    Parameters
    ----------
    phi, gamma : array_like
        Radians; φ is periodic, γ is clamped to [0, γ_max].  Broadcast together.

    Returns
    -------
    ndarray, shape (..., C)
    """
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


def evaluate(model, wi, wr, mapping: str = "deviation") -> np.ndarray:
    """f_r(wi, wr) of a model in 1/sr, shape broadcast(wi, wr)[:-1] + (C,).

    A ``kes-halfdiff`` model (several incidence angles, :mod:`kesbrdf.halfdiff`)
    defines its own (φ_h, θ_h, θ_d) mapping and ignores ``mapping``.

    >>> import numpy as np
    >>> from kesbrdf.gonio import measure
    >>> from kesbrdf.model import fit
    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> ref = AnisotropicWard(0.2, 0.2, rho_d=0.1, rho_s=0.05)
    >>> m = measure(ref)
    >>> model = fit(m)
    >>> bool(np.allclose(evaluate(model, m.wi, m.wr), m.values, rtol=1e-9))
    True
    """
    validate_mapping(mapping)
    if getattr(model, "kind", "kes") == "kes-halfdiff":
        # the (θ_h, θ_d) model defines its own mapping (kesbrdf.halfdiff)
        from kesbrdf.halfdiff import evaluate_halfdiff

        return evaluate_halfdiff(model, wi, wr)
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    wi, wr = np.broadcast_arrays(wi, wr)
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
            # ρ_KES is the measured quantity q on the paper's θ_i + θ_r = 90° line,
            # body included: c·√(cos θ_i cos θ_r) = c·√(cos γ / 2) there.
            rho = lookup(model, phi, np.abs(gamma)) + model.body * np.sqrt(
                np.clip(np.cos(gamma), 0, None) / 2
            )[..., None]
            f = rho / (norm * sin_beta)[..., None]
        else:
            phi, gamma = to_phi_gamma(wi, wr, mapping)
            f = model.body + lookup(model, phi, gamma) / norm[..., None]
    f = np.where(above[..., None], f, 0.0)
    return np.where(nan_in[..., None], np.nan, f)
