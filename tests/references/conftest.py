"""Fixtures shared by the reference-BRDF tests: a seeded rng and a hemisphere quadrature."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.geometry import spherical_to_cartesian

#: Seed of every random draw in these tests, so a failure reproduces exactly.
SEED = 20130401


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(SEED)


@pytest.fixture
def random_directions(rng):
    """A function ``n -> (n, 3)`` of unit vectors uniform on the upper hemisphere (z > 0)."""

    def draw(n: int) -> np.ndarray:
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2])
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    return draw


def directional_albedo(brdf, wr, n_theta: int = 96, n_phi: int = 192) -> np.ndarray:
    """ρ(ω_r) = ∫ f_r(ω_i, ω_r) cos θ_i dω_i over the upper hemisphere, shape (C,).

    A tensor rule: Gauss–Legendre in θ_i ∈ [0, π/2] (with the sin θ_i Jacobian) and the
    midpoint rule in φ_i, which is spectrally accurate for periodic integrands. The
    θ_i integrand is smooth even where the BRDF lobe is narrow in angle, so 96 θ nodes
    (about 1° apart) resolve lobes of a few degrees. Tests that need more pass larger
    grids.
    """
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta = (x + 1.0) * np.pi / 4.0
    w_theta = w * np.pi / 4.0
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    wi = spherical_to_cartesian(theta[:, None], phi[None, :])
    f = brdf(wi, np.asarray(wr, float))
    weights = (w_theta * np.sin(theta) * np.cos(theta))[:, None] * (2.0 * np.pi / n_phi)
    return np.einsum("ij,ijc->c", weights, f)


@pytest.fixture
def albedo():
    """The hemisphere quadrature :func:`directional_albedo`, as a fixture."""
    return directional_albedo
