"""Tests of the fibre prior (kesbrdf.models.fibre_physics) and the fibre-prior model kind (kesbrdf.models.fibre_prior)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.errors import ModelError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.models.base import kind_class
from kesbrdf.models.fibre_physics import FibrePrior, PriorSpec, fit_prior
from kesbrdf.models.fibre_prior import FibrePriorModel
from kesbrdf.validate.selection import loo_compare
from kesbrdf.references.irawan2012 import Irawan2012
from kesbrdf.references.sadeghi2013 import Sadeghi2013

SEED = 9
# The prior is symmetric in (wi, wr) expression by expression: rounding only.
RECIPROCITY_RTOL = 1e-10
# Round trip of the residual step: prior × (y / prior) reproduces y up to the KES
# table's arithmetic (1/K of an interpolant through the exact nodes): a few ulps.
ROUND_TRIP_RTOL = 1e-9
# Self-recovery: noise-free data of the model itself is refitted to a log RMS below
# 2 % (the optimiser stops at ftol 1e-8, far below this) and the parameters that the
# paper protocol identifies (k_d, the tilt range) come back within these bounds.
RECOVERY_LOG_RMS = 0.02
RECOVERY_KD_REL = 0.05
RECOVERY_UHI_DEG = 3.0
# Grazing: values must stay finite and below this multiple of the peak over the data.
GRAZING_BOUND = 1e3


def truth_prior(kinds=("filament", "filament")):
    spec = PriorSpec(kinds, 1)
    idx = spec.index()
    x = np.zeros(len(idx))
    x[idx["log_kd_0"]] = math.log(0.05)
    for fam, ks, uh, rho in (("warp", 0.08, 25.0, 0.3), ("weft", 0.03, 12.0, 0.0)):
        x[idx[f"{fam}_log_ks_0"]] = math.log(ks)
        x[idx[f"{fam}_u_lo"]] = -math.radians(uh)
        x[idx[f"{fam}_u_hi"]] = math.radians(uh)
        x[idx[f"{fam}_log_s"]] = math.log(math.radians(3.0))
        x[idx[f"{fam}_rho"]] = rho
        if f"{fam}_psi" in idx:
            x[idx[f"{fam}_psi"]] = math.radians(30.0)
    return FibrePrior(spec, x)


def hemisphere(n, rng):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def albedo(brdf, wr, n_theta=64, n_phi=128):
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta = (x + 1.0) * np.pi / 4.0
    phi = (np.arange(n_phi) + 0.5) * 2.0 * np.pi / n_phi
    wi = spherical_to_cartesian(theta[:, None], phi[None, :])
    f = brdf(wi, np.broadcast_to(wr, wi.shape))
    weights = (w * np.pi / 4.0 * np.sin(theta) * np.cos(theta))[:, None] * (2.0 * np.pi / n_phi)
    return np.einsum("ij,ijc->c", weights, f)


@pytest.fixture(scope="module")
def satin_fit():
    """One prior + residual fit to the paper protocol of a Sadeghi satin (another family)."""
    m = measure(Sadeghi2013("satin"), noise=0.01, noise_floor=1e-4, rng=SEED)
    return m, FibrePriorModel.fit_measurement(m, kinds=("filament", "filament"))


@pytest.mark.parametrize("kinds", [("filament", "filament"), ("staple", "filament"), ("staple", "staple")])
def test_prior_reciprocity_and_positivity(kinds):
    rng = np.random.default_rng(SEED)
    p = truth_prior(kinds)
    wi, wr = hemisphere(2000, rng), hemisphere(2000, rng)
    a, b = p(wi, wr), p(wr, wi)
    np.testing.assert_allclose(a, b, rtol=RECIPROCITY_RTOL)
    assert np.all(a > 0) and np.all(np.isfinite(a))


def test_filament_band_geometry():
    """A filament warp family only reflects where the half vector's tilt in the warp plane
    lies inside its tilt profile: with u ∈ ±25° and logistic edges of s = 3°, the profile
    falls by e^-8 at 8 s beyond the edge, so |atan(h_x/h_z)| > 49° is dark."""
    rng = np.random.default_rng(SEED)
    p = truth_prior()
    idx = p.spec.index()
    p.theta[idx["weft_log_ks_0"]] = -40.0
    p.theta[idx["log_kd_0"]] = -40.0
    wi, wr = hemisphere(4000, rng), hemisphere(4000, rng)
    h = wi + wr
    tilt = np.degrees(np.abs(np.arctan2(h[:, 0], h[:, 2])))
    f = p(wi, wr)[:, 0]
    inside = f[tilt < 20].mean()
    assert f[tilt > 49].max() < 1e-2 * inside


def test_fit_recovers_its_own_parameters():
    truth = truth_prior()
    m = measure(truth, orientations_deg=(0, 45, 90, 135))
    fit = fit_prior(m, kinds=("filament", "filament"))
    pred = fit(m.wi, m.wr)
    log_rms = np.sqrt(np.mean(np.log(pred / m.values) ** 2))
    assert log_rms < RECOVERY_LOG_RMS
    got, want = fit.parameters(), truth.parameters()
    assert abs(math.exp(got["log_kd_0"]) / math.exp(want["log_kd_0"]) - 1) < RECOVERY_KD_REL
    assert abs(math.degrees(got["warp_u_hi"] - want["warp_u_hi"])) < RECOVERY_UHI_DEG
    # and it predicts orientations it never saw
    held = measure(truth, orientations_deg=(22.5, 67.5, 112.5))
    held_rms = np.sqrt(np.mean(np.log(fit(held.wi, held.wr) / held.values) ** 2))
    assert held_rms < 2 * RECOVERY_LOG_RMS


def test_bic_prefers_the_true_family_kind():
    """Data of a staple warp is fitted better by a staple warp than by a filament one."""
    truth = truth_prior(("staple", "filament"))
    m = measure(truth)
    fit = fit_prior(m, kinds="auto")
    v = fit.report["variants"]
    assert v["staple/filament"]["bic"] < v["filament/filament"]["bic"]
    assert fit.report["chosen"].startswith("staple")


def test_residual_reproduces_every_measured_sample(satin_fit):
    m, model = satin_fit
    pred = model.evaluate(m.wi, m.wr)
    floor = 1e-4 * np.max(np.abs(m.values), axis=0)
    ok = m.values > floor  # dark noise below the floor cannot be reproduced by a positive model
    assert ok.mean() > 0.9
    np.testing.assert_allclose(pred[ok], m.values[ok], rtol=ROUND_TRIP_RTOL)


def test_pure_prior_option_and_relaxation(satin_fit):
    m, model = satin_fit
    pure = FibrePriorModel(model.prior, None, channels=model.channels)
    np.testing.assert_array_equal(pure.residual_ratio(m.wi, m.wr), 1.0)
    # beyond the measured γ range + the relaxation width the residual is exactly 1
    wi = spherical_to_cartesian(np.radians(89.0), np.pi)
    wr = spherical_to_cartesian(np.radians(89.0), np.pi)  # retro-reflection: γ ≈ 178°
    np.testing.assert_allclose(model.residual_ratio(wi, wr), 1.0)


def test_grazing_angles_are_finite_and_bounded(satin_fit):
    m, model = satin_fit
    peak = np.max(m.values)
    for eps in (0.0, 1e-9, 1e-300, 5e-324):
        t = np.pi / 2 - eps
        wi = spherical_to_cartesian(np.array([t, 0.3, t, 1.2]), np.array([0.0, 1.0, 2.0, 3.0]))
        wr = spherical_to_cartesian(np.array([0.2, t, t, t]), np.array([np.pi, 4.0, 0.5, 3.0]))
        f = model.evaluate(wi, wr)
        assert np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(f < GRAZING_BOUND * peak)


def test_energy_and_reciprocity_of_the_fitted_model(satin_fit):
    m, model = satin_fit
    for theta in (0.0, 45.0, 80.0):
        wr = spherical_to_cartesian(np.radians(theta), 0.7)
        assert np.all(albedo(model.prior, wr) <= 1.0)
        assert np.all(albedo(model.evaluate, wr) <= 1.0)
    rng = np.random.default_rng(SEED)
    wi, wr = hemisphere(500, rng), hemisphere(500, rng)
    np.testing.assert_allclose(model.evaluate(wi, wr), model.evaluate(wr, wi), rtol=1e-9)


def test_payload_round_trip_and_registry(satin_fit):
    m, model = satin_fit
    assert kind_class("fibre-prior") is FibrePriorModel
    fields, arrays = model.to_payload()
    again = FibrePriorModel.from_payload(fields, arrays, {"channels": model.channels})
    np.testing.assert_array_equal(again.evaluate(m.wi, m.wr), model.evaluate(m.wi, m.wr))
    with pytest.raises(ModelError, match="unknown option"):
        FibrePriorModel.fit_measurement(m, smoothing=3)
    with pytest.raises(ModelError, match="bad fibre-prior payload"):
        FibrePriorModel.from_payload({"prior": {}}, {}, {})


def test_loo_compare_reports_every_candidate():
    m = measure(Irawan2012("cotton_twill"))
    table = loo_compare(m, kinds=("filament", "filament"))
    assert set(table["orientations"]) == {"0", "45", "90", "135"}
    assert set(table["orientations"]["45"]) == {"kes", "prior", "prior+residual"}
    assert table["best"] in ("kes", "prior", "prior+residual")
    assert all(np.isfinite(v) for row in table["orientations"].values() for v in row.values())


# Calibration bounds, measured on four references at 2 % noise (docs/prior.md §5): the
# fitted-noise term alone is far too narrow (the errors are model errors), so the bands
# rest on the candidate spread and the off-support terms.  They are not Gaussian: 2σ covers
# 67–96 % (held-out orientations) and 85–99 % (hemispheres) while 1σ ranges 21–81 %.
# Asserted: the 2σ band is not badly overconfident (≥ 60 %: the lowest measured, Sadeghi
# satin, is 67 %) and stays informative (median σ of ln f below 0.5, a factor 1.65).
CAL_MIN_2SIGMA = 0.60
CAL_MAX_MEDIAN_SIGMA_LOG = 0.5
# Off the measured slice (the φ_i = 90° hemisphere) the σ of eq. U1 grows with the
# fabric's misfit to the prior (issue 20, docs/prior.md §5), because the errors there do:
# on the Sadeghi satin they have median 0.3–0.4 and 90th percentile 0.9–1.3 in ln f, and
# the band (83 % within 1σ, 98 % within 2σ on this fit) has median σ 0.79.  The
# informative bound off the slice is 0.9 (a factor 2.5, well below the cap of 3, about
# 10 % above the satin's); the 0.5 bound stays on the held-out orientations, where the
# data pin the model down (as in tests/test_uncertainty.py).
CAL_MAX_MEDIAN_SIGMA_LOG_OFF_SLICE = 0.9


@pytest.mark.parametrize("ref", [Irawan2012("cotton_twill"), Sadeghi2013("satin")], ids=["irawan_twill", "sadeghi_satin"])
def test_uncertainty_calibration(ref):
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.models.kes import fit as kes_fit
    from kesbrdf.models.fibre_prior import calibration
    from kesbrdf.validate.compare import HELD_OUT_DEG, hemisphere_directions

    m = measure(ref, noise=0.02, noise_floor=1e-4, rng=3)
    model = FibrePriorModel.fit_measurement(m, kinds=("filament", "filament"))
    kes = kes_fit(m, fallback="log")
    others = (lambda wi, wr: evaluate(kes, wi, wr, "deviation"),)
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    wr, _, _ = hemisphere_directions(5.0)
    wr = wr.reshape(-1, 3)
    wi = np.broadcast_to(spherical_to_cartesian(np.radians(30), np.radians(90)), wr.shape)
    for case, bound in ((calibration(model, ref, held.wi, held.wr, others), CAL_MAX_MEDIAN_SIGMA_LOG),
                        (calibration(model, ref, wi, wr, others), CAL_MAX_MEDIAN_SIGMA_LOG_OFF_SLICE)):
        assert case["within_2sigma"] >= CAL_MIN_2SIGMA, case
        assert case["within_1sigma"] <= case["within_2sigma"]
        assert case["median_sigma_log"] < bound, case


def test_residual_reproduces_dense_protocol_samples():
    """Several incidence lines: the residual lives on (φ_h, θ_h, θ_d) (kesbrdf.models.halfdiff)
    and every sample of every line is reproduced."""
    m = measure(Irawan2012("silk_charmeuse"), protocol="dense", step_deg=10)
    model = FibrePriorModel.fit_measurement(m, kinds=("filament", "filament"))
    assert model.residual.mode == "halfdiff"
    pred = model.evaluate(m.wi, m.wr)
    ok = m.values > 1e-4 * np.max(m.values, axis=0)
    np.testing.assert_allclose(pred[ok], m.values[ok], rtol=ROUND_TRIP_RTOL)
    fields, arrays = model.to_payload()
    again = FibrePriorModel.from_payload(fields, arrays, {"channels": model.channels})
    np.testing.assert_array_equal(again.evaluate(m.wi, m.wr), pred)


def test_few_off_slice_samples_keep_the_fixed_theta_d_law():
    """Eight out-of-plane samples beside the paper line are too few for the free θ_d law
    (d₂ ran to its bound and the law to 10⁴× at θ_i = 70°); the Fresnel law stays fixed,
    and the model stays bounded at a light the samples never saw."""
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.measure.planning import PROTOCOLS, simulate
    from kesbrdf.models.fibre_physics import MIN_THETA_D_SAMPLES, fit_prior
    from kesbrdf.references.registry import make_reference

    ref = make_reference("sadeghi-satin")
    m = simulate(ref, PROTOCOLS["paper+out-of-plane"])
    off = np.count_nonzero(np.abs(np.sum(m.wi * m.wr, axis=-1)) > 0.05)
    assert 0 < off < MIN_THETA_D_SAMPLES
    prior = fit_prior(m)
    assert not prior.report["free_theta_d"]
    wi = spherical_to_cartesian(np.radians(70.0), np.radians(45.0))
    wr = spherical_to_cartesian(np.radians(np.linspace(0, 80, 9)), np.radians(225.0))
    wi = np.broadcast_to(wi, wr.shape)
    # bounded: within 10x of the reference's brightest value on this arc (the failure was 10^4)
    assert np.max(prior(wi, wr)) < 10 * np.max(ref(wi, wr))
