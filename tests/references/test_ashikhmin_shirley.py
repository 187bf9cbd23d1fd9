"""Tests of the Ashikhmin–Shirley anisotropic Phong BRDF (JGT 5(2), 2000)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

# Reciprocity and the rotation identities evaluate the same arithmetic with permuted
# inputs; the half vector's normalisation and log/exp differ by a few ulps.
IDENTITY_RTOL = 1e-12
# The hemisphere quadrature (128 × 256 Gauss–Legendre × midpoint) converged to 1e-4 for
# exponents up to 200 and θ_i ≤ 80° (checked against 256 × 512).
QUADRATURE_ATOL = 1e-3


def sph(theta_deg, phi_deg):
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_hand_computed_value():
    """Light at the normal, viewer at 60° in the warp plane.

    h = (sin 30°, 0, cos 30°), so h·k = cos 30° = √3/2. The exponent is n_u (h lies
    along u = x), so (n·h)^10 = (3/4)^5. max(n·k1, n·k2) = 1.

    * ρ_s = √(11·101)/(8π) · (3/4)^5 / (√3/2) · [0.05 + 0.95 (1 − √3/2)^5]
      = 0.363407 × 0.050041
    * ρ_d = 28/(23π) · 0.5 · 0.95 · (1 − (1/2)^5) · (1 − (3/4)^5) = 0.135999
    """
    brdf = AshikhminShirley(n_u=10, n_v=100, R_s=0.05, R_d=0.5)
    f = brdf(sph(0, 0), sph(60, 0))
    c = math.sqrt(3.0) / 2.0
    spec = math.sqrt(11 * 101) / (8 * math.pi) * 0.75**5 / c * (0.05 + 0.95 * (1 - c) ** 5)
    diffuse = 28 / (23 * math.pi) * 0.5 * 0.95 * (1 - 0.5**5) * (1 - 0.75**5)
    assert spec + diffuse == pytest.approx(0.1541845496, rel=1e-9)
    assert f.shape == (1,)
    assert f[0] == pytest.approx(0.1541845496, rel=1e-12)
    # at normal incidence and view: h = n, F = R_s
    f_normal = brdf(sph(0, 0), sph(0, 0))[0]
    assert f_normal == pytest.approx(
        math.sqrt(1111) / (8 * math.pi) * 0.05 + 28 / (23 * math.pi) * 0.5 * 0.95 * (1 - 0.5**5) ** 2,
        rel=1e-12,
    )


def test_reciprocity(random_directions):
    brdf = AshikhminShirley(n_u=30, n_v=300, R_s=[0.04, 0.05, 0.06], R_d=[0.5, 0.3, 0.1])
    wi, wr = random_directions(5000), random_directions(5000)
    np.testing.assert_allclose(brdf(wi, wr), brdf(wr, wi), rtol=IDENTITY_RTOL, atol=0)


PARAMETER_SETS = [  # (n_u, n_v, R_s, R_d) with R_s + R_d ≤ 1
    (1, 1, 1.0, 0.0),
    (10, 100, 1.0, 0.0),
    (200, 200, 1.0, 0.0),
    (10, 100, 0.0, 1.0),
    (10, 100, 0.5, 0.5),
    (100, 10, 0.05, 0.95),
    (200, 20, 0.2, 0.8),
]
INCIDENT_GRID = [(t, p) for t in (0, 30, 60, 80) for p in (0, 45, 90)]


@pytest.mark.parametrize("n_u, n_v, R_s, R_d", PARAMETER_SETS)
def test_directional_albedo_at_most_one(albedo, n_u, n_v, R_s, R_d):
    brdf = AshikhminShirley(n_u, n_v, R_s, R_d)
    rho = np.array([albedo(brdf, sph(*g), n_theta=128, n_phi=256)[0] for g in INCIDENT_GRID])
    assert np.all(rho > 0)
    assert rho.max() <= 1.0 + QUADRATURE_ATOL, rho.max()


def test_diffuse_albedo_at_normal_incidence_is_analytic(albedo):
    """∫(1 − (1 − μ/2)^5) μ dμ over [0, 1] is 23/56, and 28/(23π) · 2π · 23/56 = 1.

    So the diffuse term's albedo at normal incidence is exactly R_d (1 − R_s)(1 − 2^−5).
    The diffuse term alone is the difference of two BRDFs that differ only in R_d.
    """
    R_s, R_d = [0.0, 0.3], [1.0, 0.6]
    full = AshikhminShirley(10, 10, R_s=R_s, R_d=R_d)
    specular = AshikhminShirley(10, 10, R_s=R_s, R_d=0.0)
    rho = albedo(lambda wi, wr: full(wi, wr) - specular(wi, wr), sph(0, 0), n_theta=128, n_phi=64)
    expected = np.array(R_d) * (1 - np.array(R_s)) * (1 - 2.0**-5)
    np.testing.assert_allclose(rho, expected, rtol=1e-9)
    assert full.channels == ("c0", "c1")


def test_anisotropy_swaps_with_the_exponents(random_directions):
    """Turning the directions by 90° about z is the same as swapping n_u and n_v."""
    wi, wr = random_directions(2000), random_directions(2000)
    brdf = AshikhminShirley(n_u=10, n_v=200, R_s=0.05, R_d=0.3)
    swapped = AshikhminShirley(n_u=200, n_v=10, R_s=0.05, R_d=0.3)
    rot = rotation_z(math.pi / 2)
    np.testing.assert_allclose(brdf(wi @ rot.T, wr @ rot.T), swapped(wi, wr), rtol=IDENTITY_RTOL)


def lobe_width(brdf, phi_deg):
    """Half-maximum width (degrees) of the lobe, light at normal incidence, scanned along φ."""
    theta = np.arange(-60.0, 60.001, 0.1)
    wr = sph(np.abs(theta), np.where(theta >= 0, phi_deg, phi_deg + 180.0))
    f = brdf(sph(0, 0), wr)[:, 0]
    above = theta[f >= 0.5 * f.max()]
    return above.max() - above.min()


def test_highlight_is_elongated_along_the_small_exponent():
    # Phong lobe (cos θ_h)^n: the half width scales like 1/√n, so the widths along x and
    # y differ by about √(n_v/n_u) = √10 ≈ 3.2. We require more than 2.
    brdf = AshikhminShirley(n_u=20, n_v=200, R_s=1.0, R_d=0.0)
    swapped = AshikhminShirley(n_u=200, n_v=20, R_s=1.0, R_d=0.0)
    along_x, along_y = lobe_width(brdf, 0.0), lobe_width(brdf, 90.0)
    assert along_x > 2.0 * along_y
    assert lobe_width(swapped, 90.0) == pytest.approx(along_x, abs=0.11)
    assert lobe_width(swapped, 0.0) == pytest.approx(along_y, abs=0.11)


def test_isotropic_limit_is_rotation_invariant(random_directions, rng):
    brdf = AshikhminShirley(n_u=50, n_v=50, R_s=[0.04, 0.5], R_d=[0.6, 0.2])
    wi, wr = random_directions(2000), random_directions(2000)
    for angle in rng.uniform(0, 2 * math.pi, size=5):
        rot = rotation_z(angle)
        np.testing.assert_allclose(brdf(wi @ rot.T, wr @ rot.T), brdf(wi, wr), rtol=IDENTITY_RTOL)


def test_per_channel_reflectances_and_channel_names():
    brdf = AshikhminShirley(10, 10, R_s=0.05, R_d=[0.1, 0.2, 0.3])
    assert brdf.channels == ("R", "G", "B")
    f = brdf(sph(20, 0), sph(40, 180))
    assert f.shape == (3,)
    grey = AshikhminShirley(10, 10, R_s=0.05, R_d=0.2)(sph(20, 0), sph(40, 180))
    assert f[1] == pytest.approx(grey[0], rel=1e-14)
    named = AshikhminShirley(10, 10, R_s=[0.04, 0.05], R_d=0.2, channels=["nm450", "nm550"])
    assert named.channels == ("nm450", "nm550")


def test_broadcasting_horizon_and_nan(random_directions):
    brdf = AshikhminShirley(10, 100, R_s=[0.05, 0.1], R_d=[0.5, 0.4])
    wi = random_directions(3)[:, None, :]
    wr = random_directions(4)[None, :, :]
    f = brdf(wi, wr)
    assert f.shape == (3, 4, 2)
    np.testing.assert_allclose(f[2, 1], brdf(wi[2, 0], wr[0, 1]), rtol=1e-14)
    up, down = sph(10, 0), np.array([0.0, 0.6, -0.8])
    assert np.all(brdf(up, down) == 0) and np.all(brdf(down, up) == 0)
    assert np.all(brdf(np.array([1.0, 0.0, 0.0]), up) == 0)
    out = brdf(np.array([[np.nan, 0, 1], [0, 0, 1]]), np.array([[0, 0, 1], [0, 0, 1]]))
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1]))


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(n_u=-1, n_v=10),
        dict(n_u=10, n_v=float("nan")),
        dict(n_u=10, n_v=10, R_s=1.5),
        dict(n_u=10, n_v=10, R_s=[0.1, 0.2], R_d=[0.1, 0.2, 0.3]),
        dict(n_u=10, n_v=10, R_d=[0.1, 0.2], channels=("R",)),
    ],
)
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(KesbrdfError, match="expected"):
        AshikhminShirley(**kwargs)


def test_params_record_rebuilds_the_brdf():
    import json

    brdf = AshikhminShirley(50, 400, R_s=0.1, R_d=[0.3, 0.25, 0.2])
    record = json.loads(json.dumps(brdf.params()))
    assert record.pop("reference") == "ashikhmin_shirley"
    again = AshikhminShirley(**record)
    w1, w2 = sph(20, 10), sph(35, 200)
    np.testing.assert_array_equal(again(w1, w2), brdf(w1, w2))
