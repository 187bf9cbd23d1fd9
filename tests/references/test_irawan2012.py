"""Tests of the far-field Irawan & Marschner (2012) woven-cloth reference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.references.irawan2012 import PRESET_NAMES, PRESETS, Irawan2012, radius_of_curvature, with_ks

# Every factor is a symmetric expression of (wi, wr) (h, wi + wr, wi·wr, the symmetric
# Seeliger law), so swapping the arguments changes only the rounding.
RECIPROCITY_RTOL = 1e-12
# The twist-reversal identity is exact geometry (v* → −v*); only rounding differs.
MIRROR_RTOL = 1e-12
# Measured L1 asymmetry of the twill's warp lobe under the across-yarn mirror: 0.49.
# A lobe that ignored the twist (e.g. the filament one) has 0; 0.2 is far from both.
STAPLE_ASYMMETRY_MIN = 0.2
# Measured centroid of the twill's warp highlight along the warp cone: ±5.4°.
CENTROID_SHIFT_MIN_DEG = 2.0
# The 96 x 192 rule agrees with 300 x 600 to 1e-5 on these presets (measured); energy
# conservation is asserted with that margin.
ALBEDO_MAX = 1.0 - 1e-4


def sph(theta_deg, phi_deg):
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_reciprocity(name, random_directions):
    f = Irawan2012(name)
    wi, wr = random_directions(600), random_directions(600)
    a, b = f(wi, wr), f(wr, wi)
    np.testing.assert_allclose(a, b, rtol=RECIPROCITY_RTOL, atol=1e-14 * a.max())
    assert np.all(a >= 0) and np.all(np.isfinite(a))


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_directional_albedo_at_most_one(name, albedo):
    f = Irawan2012(name)
    for theta, phi in [(0, 0), (80, 0), (80, 90)]:
        rho = albedo(f, sph(theta, phi))
        assert np.all(rho <= ALBEDO_MAX), (name, theta, phi, rho)
        assert np.all(rho > 0)


def test_filament_reflects_where_h_is_perpendicular_to_a_fibre_tangent(random_directions):
    """Polyester (filament warp, u_max = 22°): the warp lobe is non-zero exactly where a
    warp fibre tangent t(u) = (cos u, 0, −sin u), |u| < u_max, is perpendicular to h,
    i.e. where |atan(h_x / h_z)| < u_max (IM12's cylinder condition)."""
    weave = with_ks(PRESETS["polyester_lining"], (1, 1, 1), (0, 0, 0))
    f = Irawan2012(weave)
    wi, wr = random_directions(4000), random_directions(4000)
    lobe = f.family_lobes(wi, wr)[0]
    h = wi + wr
    tilt = np.degrees(np.abs(np.arctan2(h[:, 0], h[:, 2])))
    umax = weave.warp.umax_deg
    assert np.all(lobe[tilt > umax + 1e-9] == 0.0)
    inside = tilt < umax - 0.5
    assert np.mean(lobe[inside] > 0) > 0.97  # the Seeliger law hides only a few grazing pairs


def test_satin_streak_follows_the_warp_cone():
    """Silk charmeuse (warp floats): with light in the warp plane the highlight is a band
    along the cone wr·x = −wi·x of the warp fibres, and narrow across it."""
    f = Irawan2012(with_ks(PRESETS["silk_charmeuse"], (1, 1, 1), (0, 0, 0)))
    wi = sph(30, 180)
    mirror = np.array([np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))])
    ang = np.radians(np.arange(-80, 81, 5))
    s = np.sqrt(1 - mirror[0] ** 2)
    along = np.stack([np.full_like(ang, mirror[0]), s * np.sin(ang), s * np.cos(ang)], -1)
    across = spherical_to_cartesian(np.radians(30) + ang, 0 * ang)
    fa, fc = f(wi, along)[:, 0], f(wi, across)[:, 0]
    peak = fa[ang.size // 2]
    assert np.isclose(fc[ang.size // 2], peak)
    assert fa.min() > 0.8 * peak  # the band: bright along the whole cone
    far = np.abs(np.degrees(ang)) >= 30
    assert fc[far].max() < 0.2 * peak  # narrow across it
    # beyond the tilt range (half vector tilted more than u_max = 40°) nothing reflects
    assert np.all(fc[np.degrees(ang) > 2 * 40 - 15] == 0.0)


def test_twist_direction_moves_the_staple_highlight(random_directions):
    """Staple yarns: the twisted fibres move the highlight to one side of the yarn, and
    the twist direction (ψ → −ψ, S vs Z twist) moves it to the other side: the lobe of
    −ψ is the lobe of ψ mirrored across the yarn (fabric y → −y for the warp), exactly.
    A filament yarn has no handedness: its lobe is mirror symmetric."""
    twill = with_ks(PRESETS["cotton_twill"], (1, 1, 1), (0, 0, 0))  # warp ψ = −30°
    flipped = replace(twill, warp=replace(twill.warp, psi_deg=-twill.warp.psi_deg))
    f, g = Irawan2012(twill), Irawan2012(flipped)
    mirror = np.array([1.0, -1.0, 1.0])
    wi, wr = random_directions(3000), random_directions(3000)
    a = f.family_lobes(wi, wr)[0]
    np.testing.assert_allclose(g.family_lobes(wi * mirror, wr * mirror)[0], a, rtol=MIRROR_RTOL, atol=1e-14 * a.max())
    asym = np.abs(f.family_lobes(wi * mirror, wr * mirror)[0] - a).sum() / a.sum()
    assert asym > STAPLE_ASYMMETRY_MIN
    filament = Irawan2012(with_ks(PRESETS["polyester_lining"], (1, 1, 1), (0, 0, 0)))
    b = filament.family_lobes(wi, wr)[0]
    np.testing.assert_allclose(filament.family_lobes(wi * mirror, wr * mirror)[0], b, rtol=MIRROR_RTOL, atol=1e-14 * b.max())
    # along the warp cone (light in the warp plane) the highlight's centroid leaves the
    # plane of incidence, on opposite sides for the two twists
    light = sph(40, 180)
    ang = np.radians(np.arange(-80, 81, 2.0))
    s = np.sqrt(1 - light[0] ** 2)
    cone = np.stack([np.full_like(ang, -light[0]), s * np.sin(ang), s * np.cos(ang)], -1)
    lights = np.broadcast_to(light, cone.shape)
    centroid = [float(np.sum(h.family_lobes(lights, cone)[0] * np.degrees(ang)) / np.sum(h.family_lobes(lights, cone)[0]))
                for h in (f, g)]
    assert abs(centroid[0]) > CENTROID_SHIFT_MIN_DEG
    assert np.isclose(centroid[0], -centroid[1], atol=1e-9)


def test_the_dropped_staple_root_faces_into_the_yarn():
    """t·h = 0 has the roots v = atan2(−A, h_x) ± acos D; the module (like Irawan's code)
    keeps +.  Wherever − is on the visible half, n·h < 0, so the Seeliger law (which
    needs n·ωi, n·ωr > 0, hence n·h > 0) is zero there: dropping it loses nothing."""
    rng = np.random.default_rng(7)
    h = rng.normal(size=(20000, 3))
    h[:, 2] = np.abs(h[:, 2])
    h /= np.linalg.norm(h, axis=1)[:, None]
    u = rng.uniform(-np.radians(40), np.radians(40), h.shape[0])
    psi = np.radians(rng.choice([-60.0, -30.0, 30.0, 45.0], h.shape[0]))
    A = h[:, 1] * np.sin(u) + h[:, 2] * np.cos(u)
    B = h[:, 1] * np.cos(u) - h[:, 2] * np.sin(u)
    D = B / (np.sqrt(h[:, 0] ** 2 + A**2) * np.tan(psi))
    v = np.mod(np.arctan2(-A, h[:, 0]) - np.arccos(np.clip(D, -1, 1)) + np.pi, 2 * np.pi) - np.pi
    visible = (np.abs(D) < 1) & (np.abs(v) < np.pi / 2)
    n = np.stack([np.sin(v), np.sin(u) * np.cos(v), np.cos(u) * np.cos(v)], -1)
    assert visible.mean() > 0.05  # the root is often visible (measured 0.095)...
    assert np.all(np.sum(n * h, axis=1)[visible] < 0)  # ...but always facing away


def test_circle_spine_radius():
    """κ = 0 gives a circular spine, R = l / (2 sin u_max) − w/2, the same for every u."""
    R = radius_of_curvature(np.radians([0, 10, 30]), np.radians(30), 0.0, 1.0, 6.0)
    np.testing.assert_allclose(R, 6.0 / (2 * np.sin(np.radians(30))) - 0.5)


def test_below_horizon_and_nan():
    f = Irawan2012("cotton_twill")
    out = f(np.array([[0, 0, -1.0], [np.nan, 0, 1]]), np.array([[0, 0, 1.0], [0, 0, 1]]))
    assert np.all(out[0] == 0) and np.all(np.isnan(out[1]))


def test_unknown_preset():
    with pytest.raises(KesbrdfError, match="unknown Irawan-Marschner preset"):
        Irawan2012("tweed")
