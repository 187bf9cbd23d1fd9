"""fit_scattered: the KES table fitted to scattered gonio data (CUReT geometry).

Synthetic cases put known BRDFs, turned by a known warp azimuth, at the 205 CUReT
configurations of the committed extract (tests/data/curet_fabrics.csv), add seeded
5 % log-normal noise and hold out every fifth configuration.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from kesbrdf.models.brdf import evaluate
from kesbrdf.errors import KesbrdfError, MeasurementError
from kesbrdf.measure.gonio import measure
from kesbrdf.io.measurement_csv import read_measurement
from kesbrdf.measure.measurement import Measurement
from kesbrdf.io.model_file import load_model as load
from kesbrdf.models.kes import fit
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.models.scattered import (
    RotatedBRDF,
    evaluate_sample_frame,
    fit_scattered,
    fit_ward,
    to_fabric_frame,
)
from kesbrdf.validate.compare import metrics

EXTRACT = Path(__file__).resolve().parent / "data" / "curet_fabrics.csv"

#: Multiplicative noise of the synthetic data (σ of ln f): the floor of any held-out log-RMSE.
NOISE = 0.05
#: Held-out log-RMSE bound for a well-specified synthetic case: the noise floor 0.05
#: plus the estimation error of ~90 regularised parameters from 164 samples (measured
#: 0.067 and 0.073 for the KES truth; 0.065 for the halfvector Ward).
WELL_SPECIFIED_LOG_RMSE = 0.09
#: Warp azimuth recovery, degrees: measured 0.15° and 0.23° for the KES truth (exact
#: family); 3° for the Ward with the halfvector mapping.  5° leaves room for round-off
#: differences in the search between platforms.
WARP_TOL_DEG = 5.0
#: Reciprocity of the deviation mapping holds to round-off in φ and γ.
RECIPROCITY_RTOL = 1e-9
#: The fast residual reproduces brdf.evaluate of the final model (same table, lookup).
CONSISTENCY_RTOL = 1e-9


def _angle_diff_deg(a, b, period=180.0):
    d = (a - b) % period
    return min(d, period - d)


@pytest.fixture(scope="module")
def curet():
    return read_measurement(EXTRACT)


def _channel(m, prefix):
    k = [i for i, c in enumerate(m.channels) if c.startswith(prefix)][0]
    return Measurement(m.theta_i, m.phi_i, m.theta_r, m.phi_r, m.values[:, k:k + 1])


def _simulate(curet, brdf, warp_deg, seed=20261122):
    rng = np.random.default_rng(seed)
    ref = RotatedBRDF(brdf, math.radians(warp_deg))
    f = ref(curet.wi, curet.wr) * np.exp(rng.normal(0.0, NOISE, (len(curet), 1)))
    m = Measurement(curet.theta_i, curet.phi_i, curet.theta_r, curet.phi_r, f)
    test = np.arange(len(m)) % 5 == 0
    return m.subset(~test), m.subset(test)


def _held_out(model, test):
    return metrics(evaluate_sample_frame(model, test.wi, test.wr), test.values)["all"]["log_rmse"]


@pytest.fixture(scope="module")
def kes_truth():
    """A deviation-mapping KES model built by kesbrdf.models.kes.fit from an anisotropic Ward."""
    return fit(measure(AnisotropicWard(0.15, 0.4, rho_d=0.4, rho_s=0.15)), fallback="log", mapping="deviation")


@pytest.fixture(scope="module")
def kes_case(curet, kes_truth):
    train, test = _simulate(curet, lambda wi, wr: evaluate(kes_truth, wi, wr), 110.0)
    return train, test, fit_scattered(train)


def test_recovers_synthetic_kes_model_and_warp(kes_case):
    train, test, model = kes_case
    assert model.kind == "kes"
    assert model.parameters["symmetry"] == "central"  # CUReT covers half the azimuth circle
    assert _angle_diff_deg(model.parameters["warp_offset_deg"], 110.0) < WARP_TOL_DEG
    assert _held_out(model, test) < WELL_SPECIFIED_LOG_RMSE
    # body of the truth: ρ_d/π = 0.127 1/sr; the fit finds it within 10 %
    assert model.body[0] == pytest.approx(0.4 / np.pi, rel=0.1)


def test_kes_with_body_beats_isotropic_curve_on_anisotropic_data(kes_case):
    train, test, model = kes_case
    iso = fit_scattered(train, symmetry="isotropic")
    assert iso.parameters["symmetry"] == "isotropic"
    # measured 0.073 vs 0.161: require a clear margin, not a tie
    assert _held_out(model, test) < 0.7 * _held_out(iso, test)


def test_recovers_synthetic_ward_with_halfvector_mapping(curet):
    train, test = _simulate(curet, AnisotropicWard(0.15, 0.4, rho_d=0.4, rho_s=0.15), 30.0)
    model = fit_scattered(train, mapping="halfvector")
    assert model.parameters["mapping"] == "halfvector"
    assert _angle_diff_deg(model.parameters["warp_offset_deg"], 30.0) < WARP_TOL_DEG
    assert _held_out(model, test) < WELL_SPECIFIED_LOG_RMSE


def test_deviation_mapping_on_ward_data_still_beats_the_isotropic_curve(curet):
    # Ward is a half-vector lobe, so the default deviation mapping is mis-specified here
    # (measured 0.118 held out vs 0.065 with halfvector); it must still beat the
    # isotropic curve (measured 0.170) on anisotropic data.
    train, test = _simulate(curet, AnisotropicWard(0.15, 0.4, rho_d=0.4, rho_s=0.15), 30.0)
    kes_body = _held_out(fit_scattered(train), test)
    iso = _held_out(fit_scattered(train, symmetry="isotropic"), test)
    assert kes_body < 0.85 * iso


def test_fast_residual_reproduces_brdf_evaluate(kes_case):
    train, _, model = kes_case
    f = evaluate_sample_frame(model, train.wi, train.wr)
    eps = 1e-3 * np.max(np.abs(train.values))
    log_rmse = np.sqrt(np.mean(np.log((f + eps) / (np.maximum(train.values, 0) + eps)) ** 2))
    assert log_rmse == pytest.approx(model.diagnostics["train_log_rmse"][0], rel=CONSISTENCY_RTOL)


def test_fitted_model_is_reciprocal_positive_and_finite(kes_case, random_pairs):
    _, _, model = kes_case
    wi, wr = random_pairs
    f = evaluate(model, wi, wr)
    np.testing.assert_allclose(f, evaluate(model, wr, wi), rtol=RECIPROCITY_RTOL)
    assert np.all(np.isfinite(f)) and np.all(f > 0)
    assert np.all(np.isfinite(model.table)) and np.all(model.table >= 0)
    assert model.table.shape == (model.phi_grid.size, model.gamma_grid.size, 1)


def test_model_file_round_trip_keeps_the_warp(kes_case, tmp_path, random_pairs):
    _, _, model = kes_case
    back = load(model.save(tmp_path / "scattered.kes.json"))
    wi, wr = random_pairs
    assert back.parameters["warp_offset_deg"] == model.parameters["warp_offset_deg"]
    np.testing.assert_array_equal(evaluate_sample_frame(back, wi, wr), evaluate_sample_frame(model, wi, wr))


def test_given_warp_is_used_and_pure_lobe_has_no_body(kes_case):
    train, _, _ = kes_case
    model = fit_scattered(train, warp_deg=110.0, body="none")
    assert model.parameters["warp_offset_deg"] == pytest.approx(110.0)
    assert model.body[0] == 0.0
    assert np.all(np.isfinite(model.table)) and np.all(model.table >= 0)


def test_to_fabric_frame_puts_the_warp_on_x():
    w = np.array([math.cos(0.7), math.sin(0.7), 0.0])
    np.testing.assert_allclose(to_fabric_frame(w, 0.7), [1.0, 0.0, 0.0], atol=1e-15)


def test_auto_symmetry_uses_the_odd_part_when_the_circle_is_covered(rng):
    n = 240
    wi_t, wr_t = np.arccos(rng.uniform(0.2, 1, n)), np.arccos(rng.uniform(0.2, 1, n))
    phi_i = rng.uniform(0, 2 * np.pi, n)
    ref = AnisotropicWard(0.2, 0.3, rho_d=0.3, rho_s=0.1)
    m = Measurement(wi_t, phi_i, wr_t, phi_i + np.pi + rng.normal(0, 0.3, n), np.zeros((n, 1)))
    m.values = ref(m.wi, m.wr)
    model = fit_scattered(m, warp_deg=0.0)
    assert model.parameters["symmetry"] == "none"
    assert model.diagnostics["azimuth_gap_deg"] < 90.0


def test_fit_ward_recovers_noiseless_parameters(curet):
    truth = AnisotropicWard(0.15, 0.4, rho_d=0.4, rho_s=0.15)
    m = Measurement(curet.theta_i, curet.phi_i, curet.theta_r, curet.phi_r,
                    RotatedBRDF(truth, math.radians(30.0))(curet.wi, curet.wr))
    ward = fit_ward(m)
    # an exact family, no noise: parameters to 1 %, warp to 0.5° (α_x < α_y fixes the labels)
    got = sorted([ward.brdf.alpha_x, ward.brdf.alpha_y])
    np.testing.assert_allclose(got, [0.15, 0.4], rtol=0.01)
    np.testing.assert_allclose([ward.brdf.rho_d[0], ward.brdf.rho_s[0]], [0.4, 0.15], rtol=0.01)
    warp = math.degrees(ward.warp) + (90.0 if ward.brdf.alpha_x > ward.brdf.alpha_y else 0.0)
    assert _angle_diff_deg(warp, 30.0) < 0.5


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"symmetry": "orthotropic"}, "unknown symmetry 'orthotropic'"),
        ({"mapping": "paper"}, "expected mapping 'deviation' or 'halfvector', got 'paper'"),
        ({"body": "diffuse"}, r"expected body 'fit' \(or 'auto'\), 'none' or a number, got 'diffuse'"),
        ({"body": -0.1}, "expected a non-negative body term"),
    ],
)
def test_bad_arguments_raise(curet, kwargs, message):
    with pytest.raises(KesbrdfError, match=message):
        fit_scattered(_channel(curet, "band_s01"), **kwargs)


def test_too_few_samples_raise(curet):
    m = _channel(curet, "band_s01").subset(np.arange(len(curet)) < 6)
    with pytest.raises(MeasurementError, match="expected at least .* usable samples"):
        fit_scattered(m)


# -- real data: CUReT fabrics (committed extract) ------------------------------------
#: Held-out log-RMSE of KES + body and the isotropic curve on 5 seeded folds, as
#: measured by benchmarks/bench_real_data.py (seed 20261122); thresholds add a margin.
REAL_DATA_MARGIN = 0.01


@pytest.mark.slow  # five-fold refits on real data (~7 s each): make test-long, which CI runs
@pytest.mark.parametrize("prefix", ["band_s42_corduroy", "band_s07_velvet"])
def test_real_fabric_held_out_error_regression(curet, prefix):
    m = _channel(curet, prefix)
    labels = np.random.default_rng(20261122).permutation(len(m)) % 5
    preds = {"kes": np.empty(len(m)), "iso": np.empty(len(m))}
    for k in range(5):
        train, test = m.subset(labels != k), m.subset(labels == k)
        preds["kes"][labels == k] = evaluate_sample_frame(fit_scattered(train), test.wi, test.wr)[:, 0]
        preds["iso"][labels == k] = evaluate_sample_frame(
            fit_scattered(train, symmetry="isotropic"), test.wi, test.wr
        )[:, 0]
    err = {k: metrics(v, m.values)["all"]["log_rmse"] for k, v in preds.items()}
    expected = REAL_DATA_EXPECTED[prefix]
    assert err["kes"] < expected["kes"] + REAL_DATA_MARGIN
    assert err["iso"] < expected["iso"] + REAL_DATA_MARGIN
    if expected["kes"] < expected["iso"]:
        assert err["kes"] < err["iso"]


#: Measured by benchmarks/bench_real_data.py (pooled out-of-fold log-RMSE, 5 folds,
#: seed 20261122, default hyper-parameters): corduroy 0.148 vs 0.183, velvet 0.283 vs 0.325.
REAL_DATA_EXPECTED = {
    "band_s42_corduroy": {"kes": 0.148, "iso": 0.183},
    "band_s07_velvet": {"kes": 0.283, "iso": 0.325},
}


def test_several_channels_share_the_warp(curet):
    m = Measurement(curet.theta_i, curet.phi_i, curet.theta_r, curet.phi_r, curet.values[:, [0, 8]],
                    channels=("R", "G"))
    model = fit_scattered(m, offset_step_deg=15.0)
    assert model.channels == ("R", "G")
    assert model.table.shape[2] == 2 and model.body.shape == (2,)
    f = evaluate_sample_frame(model, m.wi, m.wr)
    assert f.shape == (len(m), 2) and np.all(f > 0)


def test_negative_values_do_not_break_the_fit(curet):
    # dark noise: a few slightly negative readings, as in some CUReT samples
    m = _channel(curet, "band_s19_rug_b")
    m.values[[3, 50, 120], 0] = -0.016
    model = fit_scattered(m, warp_deg=0.0)
    f = evaluate_sample_frame(model, m.wi, m.wr)
    assert np.all(np.isfinite(f)) and np.all(f > 0)
    assert np.all(np.isfinite(model.table)) and np.all(model.table >= 0)
