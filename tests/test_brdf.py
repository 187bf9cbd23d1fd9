"""BRDF mappings: reciprocity, horizon, NaN, broadcasting, the paper's eq. 3–4."""

import numpy as np
import pytest

from kesbrdf.models.brdf import MAPPINGS, evaluate, lookup, paper_phi_gamma, to_phi_gamma, validate_mapping
from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.models.kes import fit

#: Reciprocity by construction: (φ, γ) are computed from symmetric expressions, so only
#: round-off separates f(i, r) and f(r, i).
RECIPROCITY_RTOL = 1e-12


@pytest.fixture(scope="module")
def model():
    from kesbrdf.references.ward import AnisotropicWard

    return fit(measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1), noise=0.01, rng=1))


@pytest.mark.parametrize("mapping", ["deviation", "halfvector"])
def test_reciprocity(model, random_pairs, mapping):
    wi, wr = random_pairs
    np.testing.assert_allclose(evaluate(model, wi, wr, mapping), evaluate(model, wr, wi, mapping), rtol=RECIPROCITY_RTOL)


def test_paper_mapping_is_not_reciprocal(model, random_pairs):
    # documented property of eq. 3–4 as printed (docs/method.md, "From the table to a BRDF"): do not "fix" it silently
    wi, wr = random_pairs
    a, b = evaluate(model, wi, wr, "paper"), evaluate(model, wr, wi, "paper")
    assert np.max(np.abs(a - b) / np.abs(a)) > 0.1


def test_paper_eq4_by_hand():
    # θ_r = 60°, φ_r − φ_i = 90°: sin(β/2) = ½√(sin²(−90°) + cos²60°) = ½√1.25
    phi, gamma, sin_beta = paper_phi_gamma(np.radians(30), np.radians(10), np.radians(60), np.radians(100))
    beta = 2 * np.arcsin(0.5 * np.sqrt(1.25))
    assert sin_beta == pytest.approx(np.sin(beta), rel=1e-12)
    assert gamma == pytest.approx(np.radians(30), rel=1e-12)
    assert phi == pytest.approx(np.mod(np.pi / 2 - np.radians(110), 2 * np.pi), rel=1e-12)


def test_below_horizon_is_zero_and_nan_propagates(model):
    up = spherical_to_cartesian(0.3, 0.2)
    down = np.array([0.0, 0.6, -0.8])
    for mapping in MAPPINGS:
        assert np.all(evaluate(model, up, down, mapping) == 0)
        assert np.all(evaluate(model, down, up, mapping) == 0)
        assert np.all(np.isnan(evaluate(model, up, [np.nan, 0, 1], mapping)))


def test_broadcasting(model, rng):
    wi = spherical_to_cartesian(rng.uniform(0, 1.4, (4, 1)), rng.uniform(0, 6, (4, 1)))
    wr = spherical_to_cartesian(rng.uniform(0, 1.4, (1, 5)), rng.uniform(0, 6, (1, 5)))
    f = evaluate(model, wi, wr)
    assert f.shape == (4, 5, 3)
    np.testing.assert_allclose(f[2, 3], evaluate(model, wi[2, 0], wr[0, 3]), rtol=1e-14)


def test_in_plane_mapping_conventions():
    # ψ = 30°, γ > 0: deviation toward azimuth ψ; γ < 0: toward ψ + π (docs/method.md, "From the table to a BRDF")
    wi, wr = in_plane_directions(np.radians(30), np.radians([20, 50]), np.radians([50, 20]))
    for mapping in ("deviation", "halfvector"):
        phi, gamma = to_phi_gamma(wi, wr, mapping)
        np.testing.assert_allclose(np.degrees(phi), [30, 210], atol=1e-9)
        np.testing.assert_allclose(np.degrees(gamma), [30, 30], atol=1e-9)


def test_mirror_direction_uses_plane_of_incidence():
    wi, wr = in_plane_directions(np.radians(60), np.radians(40), np.radians(40))
    phi, gamma = to_phi_gamma(wi, wr, "deviation")
    assert gamma == pytest.approx(0, abs=1e-12)
    assert np.degrees(phi) == pytest.approx(60, abs=1e-9)


def test_lookup_is_periodic_and_clamped(model):
    a = lookup(model, 0.1, 0.2)
    np.testing.assert_allclose(lookup(model, 0.1 + 2 * np.pi, 0.2), a, rtol=1e-12)
    np.testing.assert_allclose(lookup(model, 0.1, 3.0), lookup(model, 0.1, model.gamma_max), rtol=1e-12)


def test_unknown_mapping():
    with pytest.raises(KesbrdfError, match="expected one of deviation, halfvector, paper"):
        validate_mapping("ward")


def test_energy_below_one_for_a_physical_reference(model):
    from kesbrdf.validate.diagnostics import diagnose

    d = diagnose(model)
    assert d["albedo"]["above_one"] == []
    assert d["reciprocity_error"] < 1e-12


# -- the public API at its edges (issue 8) ----------------------------------------------
#: Agreement with kesbrdf 0.1.0's evaluation: only round-off separates the optimised
#: arithmetic (flattened np.take lookup, no np.cross/hypot/mod) from the old one.
V010_RTOL = 1e-12


@pytest.mark.parametrize("mapping", MAPPINGS)
def test_identical_to_the_v010_implementation(rng, mapping):
    import brdf_v010

    from kesbrdf.models.mappings import COS_EPS
    from kesbrdf.references.ward import AnisotropicWard

    # 0.1.0 divided by √(cos θ_i cos θ_r) and held the last γ column: compare the arithmetic
    # on a table fitted so (what files written before the grazing-energy fix hold)
    model = fit(measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1), noise=0.01, rng=1),
                normalisation="sqrtcos", extrapolation="hold")

    n = 50_000
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    keep = (wi[:, 2] > COS_EPS) & (wr[:, 2] > COS_EPS)  # 0.1.0 had no horizon epsilon
    new = evaluate(model, wi[keep], wr[keep], mapping)
    old = brdf_v010.evaluate(model, wi[keep], wr[keep], mapping)
    np.testing.assert_allclose(new, old, rtol=V010_RTOL, atol=V010_RTOL * np.max(old))


@pytest.mark.parametrize("mapping", MAPPINGS)
def test_horizon_gives_exact_zero_and_grazing_stays_bounded(model, mapping):
    from kesbrdf.models.mappings import COS_EPS

    wi = spherical_to_cartesian(np.radians(90.0), 0.3)  # cos = 6e-17: at the horizon
    wr = spherical_to_cartesian(np.radians(30.0), 2.0)
    assert np.all(evaluate(model, wi, wr, mapping) == 0.0)
    assert np.all(evaluate(model, wr, wi, mapping) == 0.0)
    for tiny in (1e-300, 5e-324, 1e-7):  # denormal and sub-epsilon cosines
        assert np.all(evaluate(model, [1.0, 0.0, tiny], wr, mapping) == 0.0)
    # just above the epsilon: finite and bounded by (c + q_max / COS_EPS) / sin_beta_min
    theta = np.arccos(np.geomspace(2 * COS_EPS, 1e-2, 50))
    wi = spherical_to_cartesian(theta, np.pi)
    wr = spherical_to_cartesian(theta, 0.0)  # grazing mirror pairs: the worst case
    f = evaluate(model, wi, wr, mapping)
    bound = (model.body.max() + model.table.max()) / COS_EPS
    if mapping == "paper":
        from kesbrdf.models.mappings import PAPER_MIN_SIN_BETA

        bound /= PAPER_MIN_SIN_BETA
    assert np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(f <= bound)


@pytest.mark.parametrize("mapping", MAPPINGS)
def test_unnormalised_directions_give_the_normalised_value(model, random_pairs, mapping):
    wi, wr = random_pairs
    ref = evaluate(model, wi, wr, mapping)
    for scale_i, scale_r in ((3.7, 0.01), (1e-300, 1e300), (1e150, 2e-160)):
        np.testing.assert_allclose(evaluate(model, wi * scale_i, wr * scale_r, mapping), ref, rtol=1e-12)
    # the unnormalised mirror pair of issue 8: 0.159 1/sr, not 151.8
    mirror_i = np.array([-np.sin(0.4), 0.0, np.cos(0.4)])
    mirror_r = np.array([np.sin(0.4), 0.0, np.cos(0.4)])
    np.testing.assert_allclose(evaluate(model, 10 * mirror_i, 0.1 * mirror_r, mapping),
                               evaluate(model, mirror_i, mirror_r, mapping), rtol=1e-12)


def test_non_finite_gives_nan_and_finite_input_never_does(model, rng):
    wr = np.array([0.2, 0.1, 0.9])
    for bad in ([np.nan, 0, 1], [np.inf, 0, 1], [0, 0, -np.inf]):
        assert np.all(np.isnan(evaluate(model, bad, wr)))
    # a random mix of finite vectors: zero vectors, below the horizon, huge and tiny
    v = rng.normal(size=(4000, 3)) * 10.0 ** rng.integers(-300, 300, size=(4000, 1))
    v[::97] = 0.0
    for mapping in MAPPINGS:
        f = evaluate(model, v, v[::-1], mapping)
        assert np.all(np.isfinite(f)) and np.all(f >= 0)


def test_chunked_evaluation_matches_one_chunk(model, random_pairs):
    from kesbrdf.models import mappings

    wi, wr = random_pairs
    whole = mappings.evaluate_pairs(model.evaluate_unit, wi, wr, model.n_channels, "deviation", chunk=10**9)
    small = mappings.evaluate_pairs(model.evaluate_unit, wi, wr, model.n_channels, "deviation", chunk=7)
    np.testing.assert_array_equal(whole, small)


def test_unsupported_mapping_is_a_one_line_error(model):
    from kesbrdf.errors import ModelError

    with pytest.raises(ModelError, match="a 'kes' model supports mapping 'deviation', 'halfvector', 'paper'; got 'halfdiff'"):
        evaluate(model, [0, 0, 1.0], [0, 0, 1.0], "halfdiff")
