"""Directions in the fabric frame (x = warp, y = weft, z = normal; docs/method.md, "Conventions").

Vectors put their components on the last axis and broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "grazing_albedo",
    "spherical_to_cartesian",
    "cartesian_to_spherical",
    "in_plane_directions",
]


def spherical_to_cartesian(theta, phi) -> np.ndarray:
    """Unit vector at polar angle ``theta`` from +z and azimuth ``phi`` from +x toward +y.

    Parameters
    ----------
    theta, phi : array_like
        Radians; broadcast together.

    Returns
    -------
    ndarray, shape (..., 3)

    >>> spherical_to_cartesian(0.0, 1.0).round(12).tolist()
    [0.0, 0.0, 1.0]
    """
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    sin_theta = np.sin(theta)
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)], axis=-1)


def cartesian_to_spherical(w) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(theta, phi)`` of vectors ``w`` (..., 3); ``phi`` in (−π, π].

    >>> t, p = cartesian_to_spherical([0.0, 1.0, 0.0])
    >>> float(np.degrees(t)), float(np.degrees(p))
    (90.0, 90.0)
    """
    w = np.asarray(w, float)
    rho = np.hypot(w[..., 0], w[..., 1])
    return np.arctan2(rho, w[..., 2]), np.arctan2(w[..., 1], w[..., 0])


def in_plane_directions(psi, theta_i, theta_r) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wr) of the in-plane geometry for orientation ``psi`` (docs/method.md, "Conventions").

    The light is at azimuth ψ + π and polar angle θ_i, the viewer at azimuth ψ and
    polar angle θ_r, so γ = θ_r − θ_i > 0 puts the viewer beyond the mirror direction.
    """
    psi = np.asarray(psi, float)
    wi = spherical_to_cartesian(theta_i, psi + np.pi)
    wr = spherical_to_cartesian(theta_r, psi)
    return wi, wr


def grazing_albedo(brdf, theta_deg, phi_deg=0.0, n_s: int = 96, n_phi: int = 192) -> np.ndarray:
    r"""Directional albedo at incidences up to grazing, shape (len(theta_deg), C).

    Here (numpy only) so the model layer can use it (:mod:`kesbrdf.models.fibre_prior`'s energy
    scale); :mod:`kesbrdf.validate.diagnostics` re-exports it.

    :math:`a(\omega_i) = \int f_r\cos\theta_r\,d\omega_r = \int_0^{2\pi}\int_0^1 f_r\,u\,du\,d\phi_r`
    with u = cos θ_r = s²: Gauss–Legendre in s ∈ (0, 1) (``n_s`` nodes, dense near the
    horizon, where the lobe of a grazing light lies) times the periodic midpoint rule
    in φ_r (``n_phi``).  On the kinds' fits to the reference families, halving both
    resolutions from (96, 192) changes the result by < 2e-3 at every θ_i ≤ 89.99°
    (``benchmarks/bench_energy.py`` records the difference to (192, 384)).

    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> lam = AnisotropicWard(0.2, 0.2, rho_d=0.5, rho_s=0.0)
    >>> [round(float(v), 6) for v in grazing_albedo(lam, [0.0, 89.99])[:, 0]]
    [0.5, 0.5]
    """
    x, w = np.polynomial.legendre.leggauss(int(n_s))
    s = 0.5 * (x + 1.0)
    u = s * s
    du = 2.0 * s * 0.5 * w
    dphi = 2 * np.pi / n_phi
    phi = (np.arange(n_phi) + 0.5) * dphi
    U, P = np.meshgrid(u, phi, indexing="ij")
    sin_r = np.sqrt(1.0 - U * U)
    wr = np.stack([sin_r * np.cos(P), sin_r * np.sin(P), U], -1).reshape(-1, 3)
    weight = (U * du[:, None] * dphi).reshape(-1)
    t = np.radians(np.atleast_1d(np.asarray(theta_deg, float)))
    p = np.radians(float(phi_deg))
    out = []
    for ti in t:
        wi = np.array([[np.sin(ti) * np.cos(p), np.sin(ti) * np.sin(p), np.cos(ti)]])
        f = np.asarray(brdf(wi, wr)).reshape(wr.shape[0], -1)
        out.append(weight @ f)
    return np.array(out)
