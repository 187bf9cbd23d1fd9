"""Tests of the anisotropic GGX + Lambertian reference (Walter 2007, Heitz 2014)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.references.ggx import AnisotropicGGX, ggx_ndf, smith_lambda

# f(wi, wr) and f(wr, wi) evaluate the same terms in another order (a sum of two Λ, the
# half vector's normalisation): a few ulps.
IDENTITY_RTOL = 1e-12
# Gauss–Legendre in θ (256 nodes on [0, π/2]) × midpoint in φ (512) converges the
# normalisation integrals of α ≥ 0.05 to better than 1e-4 (checked against 512 × 1024);
# 2e-3 leaves room for the narrowest lobe of the set.
QUADRATURE_ATOL = 2e-3


def sph(theta_deg, phi_deg):
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


def _sphere_grid(n_theta, n_phi, upper_only=True):
    """Directions and weights of ∫ … dω over the upper hemisphere (or the whole sphere)."""
    hi = math.pi / 2 if upper_only else math.pi
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta = (x + 1.0) * hi / 2.0
    w_theta = w * hi / 2.0
    phi = (np.arange(n_phi) + 0.5) * 2.0 * math.pi / n_phi
    dirs = spherical_to_cartesian(theta[:, None], phi[None, :])
    weights = (w_theta * np.sin(theta))[:, None] * (2.0 * math.pi / n_phi) * np.ones_like(phi)[None, :]
    return dirs.reshape(-1, 3), weights.ravel()


ALPHAS = [(0.05, 0.05), (0.1, 0.4), (0.6, 0.15), (1.0, 1.0)]


@pytest.mark.parametrize("ax, ay", ALPHAS)
def test_ndf_is_normalised(ax, ay):
    """∫ D(h) cos θ_h dω_h = 1 (the projected microfacet area is the macro area)."""
    h, w = _sphere_grid(256, 512)
    total = float(np.sum(ggx_ndf(h, ax, ay) * h[:, 2] * w))
    assert total == pytest.approx(1.0, abs=QUADRATURE_ATOL)


@pytest.mark.parametrize("ax, ay", ALPHAS)
@pytest.mark.parametrize("view", [(0, 0), (45, 30), (75, 100)])
def test_smith_lambda_satisfies_the_projected_area_identity(ax, ay, view):
    """Heitz 2014 eq. 2 (with G1 = 1/(1 + Λ)): ∫ G1(ω) ⟨ω·h⟩ D(h) dω_h = cos θ_ω.

    An independent check of Λ: it is the one function that makes this hold for a
    Smith microsurface, and it is computed here from D alone by quadrature.
    """
    wo = sph(*view)
    h, w = _sphere_grid(256, 512)
    g1 = 1.0 / (1.0 + smith_lambda(wo, ax, ay))
    proj = np.maximum(h @ wo, 0.0)
    total = float(g1 * np.sum(proj * ggx_ndf(h, ax, ay) * w))
    assert total == pytest.approx(float(wo[2]), abs=QUADRATURE_ATOL)


def test_isotropic_ndf_matches_walter_2007_eq_33():
    """α_x = α_y = α: D = α² / (π cos⁴θ_h (α² + tan²θ_h)²) (Walter et al. 2007 eq. 33)."""
    alpha = 0.3
    theta = np.radians(np.linspace(0, 85, 18))
    h = spherical_to_cartesian(theta, np.radians(37.0))
    walter = alpha**2 / (math.pi * np.cos(theta) ** 4 * (alpha**2 + np.tan(theta) ** 2) ** 2)
    np.testing.assert_allclose(ggx_ndf(h, alpha, alpha), walter, rtol=1e-12)


def test_agrees_with_the_export_layers_ggx():
    """The export module's GGX (Burley / KHR form of D and height-correlated V) is written
    independently: f_spec = F D V with V = G2 / (4 cos_i cos_r)."""
    from kesbrdf.export.microfacet import ggx_anisotropic_ndf, ggx_anisotropic_visibility

    rng = np.random.default_rng(7)
    n = 2000
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(0, 2 * np.pi, n))
    g = AnisotropicGGX(0.12, 0.45, eta=1.5, rho_d=0.0)
    h = (wi + wr) / np.linalg.norm(wi + wr, axis=-1, keepdims=True)
    t, b = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])  # tangent = warp (x), bitangent = weft (y)
    d = ggx_anisotropic_ndf(h, t, b, 0.12, 0.45)
    v = ggx_anisotropic_visibility(wi, wr, t, b, 0.12, 0.45)
    from kesbrdf.optics import fresnel_dielectric

    want = fresnel_dielectric(np.sum(wi * h, axis=-1), 1.5) * d * v
    np.testing.assert_allclose(g(wi, wr)[:, 0], want, rtol=1e-10)


def test_reciprocity():
    rng = np.random.default_rng(11)
    v = rng.normal(size=(2, 5000, 3))
    v[..., 2] = np.abs(v[..., 2])
    wi, wr = v / np.linalg.norm(v, axis=-1, keepdims=True)
    g = AnisotropicGGX(0.08, 0.5, eta=1.6, rho_d=[0.8, 0.3, 0.05], k_s=[1.0, 0.7, 0.4])
    np.testing.assert_allclose(g(wi, wr), g(wr, wi), rtol=IDENTITY_RTOL, atol=0)


PARAMETER_SETS = [  # (α_x, α_y, η, ρ_d): the library's extremes and beyond
    (0.05, 0.05, 1.5, 0.0),
    (0.05, 0.6, 2.5, 1.0),
    (0.3, 0.3, 1.5, 1.0),
    (1.0, 1.0, 3.0, 1.0),
    (0.6, 0.1, 1.2, 1.0),
]


@pytest.mark.parametrize("ax, ay, eta, rho_d", PARAMETER_SETS)
def test_white_furnace_albedo_at_most_one(albedo, ax, ay, eta, rho_d):
    """Directional albedo ∫ f cos θ_i dω_i ≤ 1 for every view, with a white body."""
    g = AnisotropicGGX(ax, ay, eta=eta, rho_d=rho_d, k_s=1.0)
    views = [(t, p) for t in (0, 30, 60, 80) for p in (0, 45, 90)]
    rho = np.array([albedo(g, sph(*v), n_theta=192, n_phi=384)[0] for v in views])
    assert np.all(rho > 0)
    assert rho.max() <= 1.0 + QUADRATURE_ATOL, rho.max()


def test_smooth_specular_furnace_is_fresnel(albedo):
    """A near-mirror (α = 0.05), no body: the albedo at normal view is F(0°) = ((η−1)/(η+1))²
    up to the shadowing of a slightly rough surface (G2 < 1 costs < 1 % at normal view)."""
    g = AnisotropicGGX(0.05, 0.05, eta=1.5, rho_d=0.0)
    rho = albedo(g, sph(0, 0), n_theta=384, n_phi=256)[0]
    assert rho == pytest.approx(0.04, rel=0.02)


@pytest.mark.parametrize("kwargs, where", [
    ({"alpha_x": 0.0, "alpha_y": 0.1}, "alpha_x"),
    ({"alpha_x": 0.1, "alpha_y": float("nan")}, "alpha_y"),
    ({"alpha_x": 0.1, "alpha_y": 0.1, "eta": 1.0}, "eta"),
    ({"alpha_x": 0.1, "alpha_y": 0.1, "rho_d": [0.2, 1.5, 0.1]}, "rho_d"),
    ({"alpha_x": 0.1, "alpha_y": 0.1, "rho_d": [0.2, 0.5], "k_s": [1, 1, 1]}, "same number of channels"),
])
def test_bad_parameters_are_one_line_errors(kwargs, where):
    with pytest.raises(KesbrdfError, match=where) as exc:
        AnisotropicGGX(**kwargs)
    assert "\n" not in str(exc.value)


def test_registry_builds_it_with_params():
    from kesbrdf.references.registry import make_reference

    g = make_reference("ggx", '{"alpha_x": 0.2, "eta": 1.7}')
    assert isinstance(g, AnisotropicGGX) and g.alpha_x == 0.2 and g.eta == 1.7 and g.alpha_y == 0.35
    with pytest.raises(KesbrdfError, match=r"eta \(reference ggx\): expected a number in \(1, 3\]"):
        make_reference("ggx", '{"eta": 0.9}')
