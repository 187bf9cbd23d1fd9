"""σ of kes models (kesbrdf.models.kes_sigma, eq. K1): the file, its growth off the data, its coverage."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.models.base import kind_class
from kesbrdf.models.kes_sigma import KES_SIGMA_SCALES, azimuth_gap
from kesbrdf.references.ashikhmin_shirley import AshikhminShirley
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.uncertainty import within_bands
from sigma_helpers import (assert_old_file_refuses, assert_round_trip, assert_scales_act_alone,
                           assert_sigma_is_the_noise, family_coverage, fitted_family_rows,
                           load_with_sigma_field, saved)

NOISE, SEED = 0.02, 3
WARD = AnisotropicWard(0.25, 0.08, [0.2, 0.15, 0.1], 0.1)


def _fit_kes(ref):
    return kind_class("kes").fit_measurement(measure(ref, noise=NOISE, noise_floor=1e-4, rng=SEED))


@pytest.fixture(scope="module")
def ward_file(tmp_path_factory):
    return saved(_fit_kes(WARD), tmp_path_factory.mktemp("kes_sigma"))


def _pairs():
    """In-plane pairs on and between the measured orientations, and off the slice."""
    wi, wr = in_plane_directions(np.radians([0.0, 30.0, 45.0]), np.radians([30.0] * 3), np.radians([60.0] * 3))
    off_i = spherical_to_cartesian(np.radians([30.0, 60.0]), np.radians([0.0, 200.0]))
    off_r = spherical_to_cartesian(np.radians([30.0, 85.0]), np.radians([90.0, 10.0]))
    return np.concatenate([wi, off_i]), np.concatenate([wr, off_r])


def test_sigma_round_trips_bit_identically(ward_file):
    """The σ summary and every σ it gives are the same to the bit after save and load."""
    model, path = ward_file
    assert_round_trip(model, path, *_pairs())


def test_old_file_without_sigma_loads_and_refuses(ward_file, tmp_path):
    model, path = ward_file
    assert_old_file_refuses(model, path, tmp_path, *_pairs())


@pytest.mark.parametrize("field, value", [("noise", float("nan")), ("s_gamma", []), ("s", -1.0), ("support", None)])
def test_bad_sigma_field_is_one_error(ward_file, tmp_path, field, value):
    _, path = ward_file
    msg = load_with_sigma_field(path, tmp_path, field, value)
    assert "sigma" in msg or "nan" in msg.lower()


def test_baselines_carry_no_sigma():
    """The σ is calibrated for the KES form; nearest/linear baselines do not get one."""
    m = measure(WARD, noise=NOISE, noise_floor=1e-4, rng=SEED)
    assert kind_class("kes").fit_measurement(m, interpolation="linear").sigma is None


def test_sigma_is_the_noise_on_the_measured_samples(ward_file):
    """On the measured orientations and slice d_φ = d_slice = 0: σ = n, the data's noise
    (2 % here: the uncertainty column's median relative σ, within a factor 1.2 for the
    noise floor's share on dark samples)."""
    model, _ = ward_file
    wi, wr = in_plane_directions(np.radians([0.0, 45.0, 90.0, 135.0]), np.radians([20.0] * 4), np.radians([70.0] * 4))
    assert_sigma_is_the_noise(model, wi, wr, NOISE)


def test_sigma_grows_between_orientations_and_off_the_slice(ward_file):
    model, _ = ward_file
    wi, wr = _pairs()
    _, _, sl = model.predict_sigma(wi, wr)
    on, between, bias, off_a, off_b = sl[:, 0]
    assert between > on and np.isclose(bias, on)  # 30° lies 15° from 45°; 45° is measured
    assert off_a > on and off_b > on  # θ_d = 0° and grazing: off the measured θ_d = 45° slice
    # the azimuth gap is the deviation azimuth's distance to the measured half-azimuths
    assert np.allclose(azimuth_gap(np.radians([0.0, 30.0, 200.0, 350.0]), 4), np.radians([0.0, 15.0, 20.0, 10.0]))
    assert np.allclose(azimuth_gap(np.radians([112.5, 135.0]), 3), np.radians([22.5, 45.0]))


# --- coverage on held-out truths (docs/decisions.md, "σ of kes models") --------------------
# At the frozen scales (KES_SIGMA_SCALES) benchmarks/bench_calibrate_sigma.py measures, on
# the kes fit of every reference (2 % noise, paper protocol), family means [within 1σ,
# within 2σ] on the held-out orientations ψ = 15…165°:
#   Ward [0.77, 0.96]   Ashikhmin–Shirley [0.76, 0.93]   (Irawan [0.73, 0.92],
#   Sadeghi [0.79, 0.91], felt [0.68, 0.93]: all five in the bands ± 0.05)
# and on the Fig. 6 hemispheres Ward [0.96, 0.99] (too wide at 1σ: a miss, recorded),
# Ashikhmin–Shirley [0.48, 0.75] (too narrow: the KES mapping's error off the slice on
# that lobe is not visible in slice data; a miss, recorded).  Tested here: the held-out
# orientations of Ward and Ashikhmin–Shirley (both kes by default, 2 references each,
# ~1 s of fits) inside the bands ± FAMILY_BAND_TOL, and Ward's hemispheres (10° grid)
# never overconfident (within 2σ ≥ 0.90 − tol).  FAMILY_BAND_TOL = 0.05 as in
# tests/test_uncertainty.py: neighbouring directions share their errors, so of ~500
# truths per case only about a hundred are independent (binomial sd ≈ 0.046 near 0.7).
# The same σ halved (or doubled) leaves the bands (last test).
FAMILY_BAND_TOL = 0.05
HEMI_STEP_DEG = 10.0
FAMILIES = {
    "ward": (WARD, AnisotropicWard(0.1, 0.3, 0.3, 0.05)),
    "ashikhmin_shirley": (AshikhminShirley(10, 100, R_s=0.05, R_d=[0.5, 0.3, 0.2]),
                          AshikhminShirley(300, 30, R_s=0.1, R_d=0.3)),
}


@pytest.fixture(scope="module")
def family_cases(tmp_path_factory):
    """{family: [(case, f, σ_ln f, truth)]} from saved-and-loaded kes files."""
    return fitted_family_rows(tmp_path_factory.mktemp("kes_cov"), FAMILIES, _fit_kes, "paper",
                              lambda fam: fam == "ward", HEMI_STEP_DEG)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_held_out_orientations_inside_the_bands(family, family_cases):
    c1, c2 = family_coverage(family_cases[family])["held_out"]
    assert within_bands(c1, c2, tol=FAMILY_BAND_TOL), (family, c1, c2)


def test_ward_hemispheres_are_not_overconfident(family_cases):
    """The hemispheres are over-covered at 1σ (a recorded miss), never under-covered."""
    cov = family_coverage(family_cases["ward"])
    for case in ("hemi90", "hemi45"):
        c1, c2 = cov[case]
        assert c1 >= 0.60 - FAMILY_BAND_TOL and c2 >= 0.90 - FAMILY_BAND_TOL, (case, c1, c2)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_rescaled_sigma_leaves_the_bands(factor, family_cases):
    """The band check can fail: σ halved or doubled takes a family's held-out orientations
    out of the bands."""
    for fam, rows in family_cases.items():
        c1, c2 = family_coverage(rows, factor)["held_out"]
        assert not within_bands(c1, c2, tol=FAMILY_BAND_TOL), (fam, factor, c1, c2)


def test_frozen_scales_are_the_calibrated_ones(ward_file):
    """KES_SIGMA_SCALES are the grid point bench_calibrate_sigma.py chose on all five
    families (2026-12-03; a change must come with a new calibration run), and each scale
    acts on its own term: a larger azimuth scale widens σ between orientations only, a
    larger slice scale off the slice only."""
    assert KES_SIGMA_SCALES == {"azimuth": 1.0, "azimuth_power": 1.0, "slice": 0.3, "slice_misfit": 3.0}
    model, _ = ward_file
    assert_scales_act_alone(model, *_pairs(), between=[1], on_phi=[0, 2], off=[3, 4], on_slice=[0, 1, 2])
