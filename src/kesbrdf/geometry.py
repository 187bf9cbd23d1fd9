"""Directions in the fabric frame (x = warp, y = weft, z = normal; DESIGN §2).

Vectors put their components on the last axis and broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np

__all__ = [
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
    """(wi, wr) of the in-plane geometry for orientation ``psi`` (DESIGN §2).

    The light is at azimuth ψ + π and polar angle θ_i, the viewer at azimuth ψ and
    polar angle θ_r, so γ = θ_r − θ_i > 0 puts the viewer beyond the mirror direction.
    """
    psi = np.asarray(psi, float)
    wi = spherical_to_cartesian(theta_i, psi + np.pi)
    wr = spherical_to_cartesian(theta_r, psi)
    return wi, wr
