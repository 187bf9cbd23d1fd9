import numpy as np

from kesbrdf.geometry import cartesian_to_spherical, in_plane_directions, spherical_to_cartesian


def test_spherical_round_trip(rng):
    theta = rng.uniform(0, np.pi / 2, 100)
    phi = rng.uniform(-np.pi, np.pi, 100)
    t, p = cartesian_to_spherical(spherical_to_cartesian(theta, phi))
    np.testing.assert_allclose(t, theta, atol=1e-12)
    np.testing.assert_allclose(p, phi, atol=1e-12)


def test_in_plane_convention():
    # light at azimuth ψ + π, viewer at ψ (docs/method.md, "Conventions")
    wi, wr = in_plane_directions(0.0, np.radians(30), np.radians(30))
    np.testing.assert_allclose(wi, [-0.5, 0, np.cos(np.radians(30))], atol=1e-12)
    np.testing.assert_allclose(wr, [0.5, 0, np.cos(np.radians(30))], atol=1e-12)
