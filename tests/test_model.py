"""Model fitting: round trips, isotropic exactness, hazards, file format."""

import json

import numpy as np
import pytest

from kesbrdf.models.brdf import evaluate
from kesbrdf.errors import KESError, MeasurementError, ModelError
from kesbrdf.measure.gonio import measure
from kesbrdf.io.model_file import load_model as load
from kesbrdf.models.kes import fit
from kesbrdf.references.ward import AnisotropicWard

#: Exact reproduction of inputs: only float round-off through trig and the lookup.
ROUND_TRIP_RTOL = 1e-12


@pytest.mark.parametrize("mapping", ["deviation", "halfvector"])
@pytest.mark.parametrize("orientations", [3, 4])
def test_round_trip_reproduces_every_input_sample(ward, mapping, orientations):
    m = measure(ward, noise=0.02, rng=3)
    model = fit(m, orientations=orientations)
    used = np.ones(len(m), bool) if orientations == 4 else np.degrees(m.psi) < 100
    f = evaluate(model, m.wi[used], m.wr[used], mapping)
    np.testing.assert_allclose(f, m.values[used], rtol=ROUND_TRIP_RTOL)


def test_round_trip_with_noise_floor_only_moves_floored_samples():
    # a pure lobe with no body: far from the highlight q → 0 and is floored
    ref = AnisotropicWard(0.1, 0.2, rho_d=0.0, rho_s=0.2)
    m = measure(ref)
    model = fit(m, body="none", fallback="log")
    assert model.diagnostics["floored"], "expected floored half-samples for a pure lobe"
    f = evaluate(model, m.wi, m.wr)
    floor = model.diagnostics["noise_floor"][0]
    w = np.sqrt(np.cos(m.theta_i) * np.cos(m.theta_r))
    # every sample is reproduced exactly or raised to at most the floor
    assert np.all(np.abs(f[:, 0] - m.values[:, 0]) <= floor / w * (1 + 1e-9))


def test_isotropic_reference_is_matched_at_every_orientation(rng):
    iso = AnisotropicWard(0.2, 0.2, rho_d=0.3, rho_s=0.1)
    model = fit(measure(iso))
    psi = rng.uniform(0, 180, 7)
    held = measure(iso, orientations_deg=psi)
    np.testing.assert_allclose(evaluate(model, held.wi, held.wr), held.values, rtol=1e-10)
    # and φ-independence everywhere in the table
    spread = model.table.max(axis=0) - model.table.min(axis=0)
    assert np.max(spread) < 1e-10 * model.table.max()


def test_kes_beats_both_baselines_at_held_out_orientations(ward):
    from kesbrdf.validate.compare import compare_reference

    m = measure(ward, noise=0.01, rng=5)
    result = compare_reference(m, ward)
    for baseline in ("nearest", "linear"):
        assert result["ratio_kes_to"][baseline]["held_out_orientations"] < 0.6
        for case, ratio in result["ratio_kes_to"][baseline].items():
            assert ratio < 1.0, (baseline, case, ratio)


def test_negative_kes_detected_and_log_fallback_recorded():
    ref = AnisotropicWard(0.08, 0.3, rho_d=0.0, rho_s=0.3)  # very different warp/weft, no body
    m = measure(ref)
    with pytest.raises(KESError, match="K\\(phi\\) = 1/rho <= 0 .* fallback='log'"):
        fit(m, body="none", fallback="error")  # the --strict behaviour
    model = fit(m, body="none")  # default: recorded log fallback with a warning
    assert model.parameters["fallback"] == "log"
    assert model.diagnostics["fallback_gamma_deg"]
    (warning,) = model.diagnostics["warnings"]
    first = f"{model.diagnostics['fallback_gamma_deg'][0]:g}"
    assert "gamma = " in warning and first in warning and "\n" not in warning
    assert np.all(np.isfinite(model.table)) and np.all(model.table >= 0)


def test_nonpositive_inputs_are_floored_and_reported():
    ref = AnisotropicWard(0.15, 0.25, rho_d=0.0, rho_s=0.1)
    m = measure(ref, noise_floor=1e-3, rng=1)  # dark noise: some negative values
    assert np.any(m.values < 0)
    model = fit(m, body="none", fallback="log")
    assert len(model.diagnostics["floored"]) > 0
    assert np.all(np.isfinite(model.table)) and np.all(model.table >= 0)


def test_missing_orientations_raise():
    m = measure(AnisotropicWard(0.2, 0.2), orientations_deg=(0, 45))
    with pytest.raises(MeasurementError, match="missing 90"):
        fit(m)
    m3 = measure(AnisotropicWard(0.2, 0.2), orientations_deg=(0, 45, 90))
    assert fit(m3).orientations == 3
    with pytest.raises(MeasurementError, match="needs psi = 135"):
        fit(m3, orientations=4)


def test_residual_135_measures_asymmetry():
    sym = fit(measure(AnisotropicWard(0.1, 0.2)))
    assert sym.diagnostics["residual_135"]["value"]["max_abs_rel"] < 1e-12


def test_save_load_gives_identical_model(tmp_path, ward):
    model = fit(measure(ward, noise=0.01, rng=2), fallback="log")
    path = model.save(tmp_path / "m.kes.json")
    again = load(path)
    for name in ("phi_grid", "gamma_grid", "table", "body", "gamma_nodes", "q_nodes"):
        np.testing.assert_array_equal(getattr(again, name), getattr(model, name))
    assert again.parameters == model.parameters and again.channels == model.channels
    doc = json.loads(path.read_text())
    assert doc["format"] == "kesbrdf-model" and doc["format_version"] == 1 and doc["kesbrdf_version"]
    assert "pickle" not in path.read_text()


def test_model_file_records_input_hash(tmp_path, ward):
    from kesbrdf.io.measurement_csv import read_measurement, write_measurement

    csv = write_measurement(tmp_path / "m.csv", measure(ward))
    m = read_measurement(csv)
    model = fit(m)
    import hashlib

    assert model.input_info["sha256"] == hashlib.sha256(csv.read_bytes()).hexdigest()


@pytest.mark.parametrize("text,match", [
    ("not json", "invalid JSON"),
    ('{"format": "other"}', "expected format"),
    ('{"format": "kesbrdf-model", "format_version": 99}', "version 1, got 99"),
    ('{"format": "kesbrdf-model", "format_version": 1, "arrays": {}}', "missing array"),
])
def test_bad_model_files(tmp_path, text, match):
    p = tmp_path / "bad.kes.json"
    p.write_text(text)
    with pytest.raises(ModelError, match=match):
        load(p)


def test_dense_data_uses_the_90_degree_line():
    m = measure(AnisotropicWard(0.15, 0.25, rho_d=0.1), protocol="dense", step_deg=6)
    model = fit(m)
    assert model.diagnostics["incidence_line_deg"] == pytest.approx(90.0)
    assert model.diagnostics["unused_rows"] > 0


def test_kes_table_has_no_spike_where_k_nears_zero():
    """Where K(φ) = 1/ρ comes close to 0 without crossing it, ρ = 1/K spiked (a user's
    satin: B = 6.3 1/sr at γ = 80°, neighbours and truth ≈ 0.05–0.07).  Such rows now
    fall back like K ≤ 0, so no table value exceeds OVERSHOOT × the brightest measured
    orientation at its γ (the bound is the rule itself; the log fallback is held within
    the measured range)."""
    from kesbrdf.models.kes import OVERSHOOT
    from kesbrdf.references.registry import make_reference

    m = measure(make_reference("sadeghi-satin"), noise=0.01, rng=1)
    model = fit(m, fallback="log")
    brightest = np.nanmax(model.q_nodes, axis=1)  # (γ nodes, C), body included
    # compare on the γ nodes (the table's γ grid interpolates linearly between them)
    rows = [int(np.argmin(np.abs(model.gamma_grid - g))) for g in model.gamma_nodes]
    assert np.all(model.table[:, rows, :] <= OVERSHOOT * brightest[None] * (1 + 1e-9))
    assert 80.0 in [round(g) for g in model.diagnostics["fallback_gamma_deg"]]


#: Fig. 6 hemisphere NRMSE of the paper protocol's table of an anisotropic Ward (α 0.1 /
#: 0.25), read off the plane with the half-vector and the deviation mapping: measured
#: 0.041 and 0.077 (ratio 0.54; the deviation reading gives an off-plane lobe its in-plane
#: width).  The half-vector reading must be at most 0.7 of the deviation one; a swapped or
#: broken mapping default gives ratio 1.
HALFVECTOR_GAIN_MAX = 0.7


def test_new_fits_record_and_use_the_half_vector_mapping():
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard
    from kesbrdf.validate.lofo import score, scoring_truths

    ref = AnisotropicWard(0.1, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.08)
    m = measure(ref, noise=0.02, rng=3)
    model = fit(m)
    assert model.parameters["mapping"] == "halfvector" == model.default_mapping
    t = scoring_truths(ref)
    half = score(model.evaluate, None, t)
    dev = score(lambda wi, wr: model.evaluate(wi, wr, "deviation"), None, t)
    assert half["hemispheres"] < HALFVECTOR_GAIN_MAX * dev["hemispheres"], (half, dev)
    assert half["orientations"] == pytest.approx(dev["orientations"], rel=1e-9)  # the plane is the same
    # a file that records no mapping is read as it was fitted, with the deviation mapping
    params = {k: v for k, v in model.parameters.items() if k != "mapping"}
    old = type(model)(**{**model.__dict__, "parameters": params})
    assert old.default_mapping == "deviation"
    np.testing.assert_array_equal(old.evaluate(t["hemis"][0][0], t["hemis"][0][1]),
                                  model.evaluate(t["hemis"][0][0], t["hemis"][0][1], "deviation"))
