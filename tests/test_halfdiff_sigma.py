"""σ of kes-halfdiff models (kesbrdf.models.halfdiff_sigma, eq. K1 with the halfdiff
coordinates): the file, its growth off the data, its coverage, and ``eval --uncertainty``."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.io.model_file import load_model as load
from kesbrdf.measure.gonio import measure
from kesbrdf.models.base import kind_class
from kesbrdf.models.halfdiff_sigma import HALFDIFF_SIGMA_SCALES, support_distance
from kesbrdf.references.irawan2012 import PRESET_NAMES as IRAWAN_PRESETS, Irawan2012
from kesbrdf.references.sadeghi2013 import PRESET_NAMES as SADEGHI_PRESETS, Sadeghi2013
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.uncertainty import predict_sigma, within_bands
from sigma_helpers import (assert_old_file_refuses, assert_round_trip, assert_scales_act_alone,
                           assert_sigma_is_the_noise, family_coverage, fitted_family_rows,
                           load_with_sigma_field, saved)

NOISE, SEED = 0.02, 3
WARD = AnisotropicWard(0.25, 0.08, [0.2, 0.15, 0.1], 0.1)
#: θ_max of the dense protocol at its default 6° step (largest θ_i, θ_r measured).
THETA_MAX_DEG = 84.0


def _dense(ref):
    return measure(ref, protocol="dense", noise=NOISE, noise_floor=1e-4, rng=SEED)


def _fit(ref):
    return kind_class("kes-halfdiff").fit_measurement(_dense(ref))


@pytest.fixture(scope="module")
def ward_file(tmp_path_factory):
    return saved(_fit(WARD), tmp_path_factory.mktemp("hd_sigma"))


def _pairs():
    """On a measured orientation, between two (ψ = 22.5°), and two pairs off the
    measured (θ_h, θ_d) support on a measured half-azimuth: retro-reflection (θ_h = 30° >
    θ_d = 0: light and viewer on one side) and a viewer at 89° (θ_h + θ_d = 89° > 84°)."""
    wi, wr = in_plane_directions(np.radians([0.0, 22.5, 0.0]), np.radians([30.0] * 3), np.radians([60.0, 60.0, 89.0]))
    retro = spherical_to_cartesian(np.radians(30.0), 0.0)[None]
    return np.concatenate([wi, retro]), np.concatenate([wr, retro])


def test_fresh_dense_fit_carries_sigma(ward_file):
    model, _ = ward_file
    assert model.has_sigma and model.kind == "kes-halfdiff"
    s = model.sigma
    assert set(s) == {"noise", "s", "s_gamma", "gamma_bin_deg", "support"}
    assert s["support"]["theta_max_deg"] == pytest.approx(THETA_MAX_DEG)
    assert len(s["s_gamma"]) == 6 and min(s["s_gamma"]) >= 0  # 15° bins of 2θ_h to 90°


def test_sigma_round_trips_bit_identically(ward_file):
    """The σ summary and every σ it gives are the same to the bit after save and load."""
    model, path = ward_file
    assert_round_trip(model, path, *_pairs())


def test_old_file_without_sigma_loads_and_refuses(ward_file, tmp_path):
    model, path = ward_file
    assert "kes-halfdiff" in assert_old_file_refuses(model, path, tmp_path, *_pairs())


@pytest.mark.parametrize("field, value", [("noise", float("nan")), ("s_gamma", []), ("s", -1.0), ("support", None),
                                          ("support", {"theta_d_deg": [0, 84], "gamma_max_deg": 84, "psi_deg": [0]})])
def test_bad_sigma_field_is_one_error(ward_file, tmp_path, field, value):
    """Malformed fields, and a kes-style support without theta_max_deg, are one-line errors."""
    _, path = ward_file
    assert "sigma" in load_with_sigma_field(path, tmp_path, field, value)


def test_sigma_is_the_noise_on_the_measured_samples(ward_file):
    """On the measured orientations and support d_φ = d_slice = 0: σ = n (2 % here, within
    a factor 1.2 for the noise floor's share on dark samples)."""
    model, _ = ward_file
    m = _dense(WARD)
    assert_sigma_is_the_noise(model, m.wi, m.wr, NOISE)


def test_sigma_grows_between_orientations_and_off_the_support(ward_file):
    model, _ = ward_file
    wi, wr = _pairs()
    _, _, sl = model.predict_sigma(wi, wr)
    on, between, grazing, retro = sl[:, 0]
    assert np.isclose(on, model.sigma["noise"])
    assert between > on and grazing > on and retro > on
    # eq. H1: 5° past the largest measured angle, and θ_h − θ_d = 30° for the retro pair
    d = support_distance(model.sigma["support"], wi, wr)
    np.testing.assert_allclose(d, np.radians([0.0, 0.0, 89.0 - THETA_MAX_DEG, 30.0]), atol=1e-9)


# --- coverage on held-out truths (docs/decisions.md, "σ of kes-halfdiff models") ----------
# At the frozen scales (HALFDIFF_SIGMA_SCALES) benchmarks/bench_calibrate_sigma.py measures,
# on the kes-halfdiff fit of every reference (2 % noise, dense protocol at 6°, seed 3),
# family means [within 1σ, within 2σ] on the held-out orientations ψ = 15…165° (dense
# geometry) and the Fig. 6 hemispheres (5° grid):
#               held-out        hemi φ_i = 90°   φ_i = 45°
#   Irawan      [0.74, 0.87]    [0.80, 0.90]     [0.82, 0.92]
#   Sadeghi     [0.74, 0.86]    [0.69, 0.86]     [0.70, 0.86]
#   Ward        [0.84, 0.96]    [0.87, 0.98]     [0.91, 0.98]    (too wide at 1σ: a miss)
#   A.–Shirley  [0.90, 0.98]    [0.77, 0.91]     [0.82, 0.91]    (held-out too wide: a miss)
#   felt        [0.83, 0.98]    [0.70, 0.85]     [0.71, 0.84]
# Tested here: the held-out orientations of Irawan and Sadeghi (6 references each, ~1 s of
# fits; measured by this test's own truths: Irawan [0.744, 0.871], Sadeghi [0.741, 0.863])
# inside the bands ± FAMILY_BAND_TOL (0.05, as tests/test_kes_sigma.py: of a few thousand
# truths per case only about a hundred are independent, binomial sd ≈ 0.046 near 0.7).
# In-sample: the frozen scales were chosen on all five families; left out, no family is
# inside the bands on every case (docs/decisions.md).  Sadeghi's hemispheres (10° grid:
# [0.68, 0.86], [0.71, 0.85]) are inside too but within 0.001–0.008 of the 2σ edge, too
# close for a test.  The same σ halved ([0.55, 0.74], [0.60, 0.74]) or doubled ([0.87,
# 0.95], [0.86, 0.96]) leaves the bands (test_rescaled_sigma_leaves_the_bands).
FAMILY_BAND_TOL = 0.05
FAMILIES = {"irawan2012": tuple(Irawan2012(n) for n in IRAWAN_PRESETS),
            "sadeghi2013": tuple(Sadeghi2013(n) for n in SADEGHI_PRESETS)}


@pytest.fixture(scope="module")
def family_cases(tmp_path_factory):
    """{family: [(case, f, σ_ln f, truth)]} from saved-and-loaded kes-halfdiff files."""
    return fitted_family_rows(tmp_path_factory.mktemp("hd_cov"), FAMILIES, _fit, "dense", lambda fam: False)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_held_out_orientations_inside_the_bands(family, family_cases):
    c1, c2 = family_coverage(family_cases[family])["held_out"]
    assert within_bands(c1, c2, tol=FAMILY_BAND_TOL), (family, c1, c2)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_rescaled_sigma_leaves_the_bands(factor, family_cases):
    """The band check can fail: σ halved or doubled takes each family's held-out
    orientations out of the bands."""
    for fam, rows in family_cases.items():
        c1, c2 = family_coverage(rows, factor)["held_out"]
        assert not within_bands(c1, c2, tol=FAMILY_BAND_TOL), (fam, factor, c1, c2)


def test_frozen_scales_are_the_calibrated_ones(ward_file):
    """HALFDIFF_SIGMA_SCALES are the grid point bench_calibrate_sigma.py chose on all five
    families (2026-12-03; a change must come with a new calibration run), and each scale
    acts on its own term."""
    assert HALFDIFF_SIGMA_SCALES == {"azimuth": 0.5, "azimuth_power": 0.5, "slice": 2.0, "slice_misfit": 4.5}
    model, _ = ward_file
    assert model.sigma_scales is HALFDIFF_SIGMA_SCALES
    assert_scales_act_alone(model, *_pairs(), between=[1], on_phi=[0, 2, 3], off=[2, 3], on_slice=[0, 1])


def test_eval_uncertainty_on_a_kes_halfdiff_file(ward_file, tmp_path):
    """``kesbrdf eval --uncertainty`` writes σ columns for a kes-halfdiff file: σ = f·σ_ln f
    of the library, noise-sized on a measured sample, larger off the support."""
    model, path = ward_file
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n30,180,60,0\n30,202.5,60,22.5\n30,0,30,0\n")
    out = tmp_path / "o.csv"
    assert main(["eval", str(path), "--pairs", str(pairs), "-o", str(out), "--uncertainty"]) == 0
    rows = list(csv.DictReader(out.open()))
    chans = list(model.channels)
    assert list(rows[0])[4:] == chans + [f"sigma_{c}" for c in chans]
    f = np.array([[float(r[c]) for c in chans] for r in rows])
    s = np.array([[float(r[f"sigma_{c}"]) for c in chans] for r in rows])
    wi, wr = _pairs()
    lib_f, lib_s, _ = predict_sigma(load(path), wi[[0, 1, 3]], wr[[0, 1, 3]])
    np.testing.assert_allclose(f, lib_f, rtol=1e-12)
    np.testing.assert_allclose(s, lib_s, rtol=1e-12)
    assert np.allclose(s[0] / f[0], model.sigma["noise"]) and np.all(s[1:] / f[1:] > model.sigma["noise"])


@pytest.mark.slow  # an auto fit of a dense measurement (~10 s): make test-long, which CI runs
def test_default_model_of_a_dense_measurement_carries_sigma():
    """``kesbrdf.fit`` keeps kes-halfdiff on a dense Ward measurement (~10 s: the dense
    rule compares it with fibre-coord), and that default model now has a σ."""
    import kesbrdf

    model, _ = kesbrdf.fit(_dense(WARD))
    assert model.kind == "kes-halfdiff" and model.has_sigma
