"""σ of kes models (kesbrdf.models.kes_sigma, eq. K1): the file, its growth off the data, its coverage."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kesbrdf.errors import ModelError
from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.io.model_file import load_model as load
from kesbrdf.measure.gonio import measure
from kesbrdf.models.base import kind_class
from kesbrdf.models.kes_sigma import KES_SIGMA_SCALES, azimuth_gap, predict_kes_sigma
from kesbrdf.references.ashikhmin_shirley import AshikhminShirley
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.compare import HELD_OUT_DEG, hemisphere_directions
from kesbrdf.validate.uncertainty import coverage, predict_sigma, within_bands

NOISE, SEED = 0.02, 3
WARD = AnisotropicWard(0.25, 0.08, [0.2, 0.15, 0.1], 0.1)


def _fit_kes(ref):
    return kind_class("kes").fit_measurement(measure(ref, noise=NOISE, noise_floor=1e-4, rng=SEED))


@pytest.fixture(scope="module")
def ward_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("kes_sigma")
    model = _fit_kes(WARD)
    model.save(d / "k.kes.json")
    return model, d / "k.kes.json"


def _pairs():
    """In-plane pairs on and between the measured orientations, and off the slice."""
    wi, wr = in_plane_directions(np.radians([0.0, 30.0, 45.0]), np.radians([30.0] * 3), np.radians([60.0] * 3))
    off_i = spherical_to_cartesian(np.radians([30.0, 60.0]), np.radians([0.0, 200.0]))
    off_r = spherical_to_cartesian(np.radians([30.0, 85.0]), np.radians([90.0, 10.0]))
    return np.concatenate([wi, off_i]), np.concatenate([wr, off_r])


def test_sigma_round_trips_bit_identically(ward_file):
    """The σ summary and every σ it gives are the same to the bit after save and load."""
    model, path = ward_file
    again = load(path)
    assert again.has_sigma and again.sigma == model.sigma
    wi, wr = _pairs()
    for a, b in zip(model.predict_sigma(wi, wr), again.predict_sigma(wi, wr)):
        assert np.array_equal(a, b)
    # and a second save writes the same document
    again.save(path.with_name("k2.kes.json"))
    assert json.loads(path.read_text())["sigma"] == json.loads(path.with_name("k2.kes.json").read_text())["sigma"]


def test_old_file_without_sigma_loads_and_refuses(ward_file, tmp_path):
    model, path = ward_file
    doc = json.loads(path.read_text())
    del doc["sigma"]
    old = tmp_path / "old.kes.json"
    old.write_text(json.dumps(doc))
    m = load(old)
    assert not m.has_sigma and m.predict_sigma(*_pairs()) is None
    np.testing.assert_array_equal(m.evaluate(*_pairs()), model.evaluate(*_pairs()))
    with pytest.raises(ModelError) as exc:
        predict_sigma(m, *_pairs(), source=str(old))
    assert "carries no uncertainty" in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("field, value", [("noise", float("nan")), ("s_gamma", []), ("s", -1.0), ("support", None)])
def test_bad_sigma_field_is_one_error(ward_file, tmp_path, field, value):
    _, path = ward_file
    doc = json.loads(path.read_text())
    doc["sigma"][field] = value
    bad = tmp_path / "bad.kes.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelError) as exc:
        load(bad)
    assert "\n" not in str(exc.value) and ("sigma" in str(exc.value) or "NaN" in str(exc.value) or "nan" in str(exc.value).lower())


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
    _, _, sl = model.predict_sigma(wi, wr)
    assert np.allclose(sl, model.sigma["noise"])
    assert NOISE <= model.sigma["noise"] <= 1.2 * NOISE


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


def _truths(ref, hemispheres: bool):
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    out = [("held_out", held.wi, held.wr, held.values)]
    if hemispheres:
        wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
        wr = wr.reshape(-1, 3)
        for phi_i in (90.0, 45.0):
            wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(phi_i)), wr.shape)
            out.append((f"hemi{phi_i:g}", wi, wr, np.asarray(ref(wi, wr), float)))
    return out


@pytest.fixture(scope="module")
def family_cases(tmp_path_factory):
    """{family: [(case, f, σ_ln f, truth)]} from saved-and-loaded kes files."""
    d = tmp_path_factory.mktemp("kes_cov")
    out = {}
    for fam, refs in FAMILIES.items():
        rows = []
        for k, ref in enumerate(refs):
            _fit_kes(ref).save(d / f"{fam}{k}.kes.json")
            model = load(d / f"{fam}{k}.kes.json")
            for case, wi, wr, truth in _truths(ref, fam == "ward"):
                f, _, sl = predict_sigma(model, wi, wr)
                rows.append((case, f, sl, truth))
        out[fam] = rows
    return out


def _family_coverage(rows, factor=1.0) -> dict:
    out = {}
    for case in dict.fromkeys(c for c, *_ in rows):
        cov = [coverage(f, factor * sl, t) for c, f, sl, t in rows if c == case]
        out[case] = (np.mean([c["within_1sigma"] for c in cov]), np.mean([c["within_2sigma"] for c in cov]))
    return out


@pytest.mark.parametrize("family", list(FAMILIES))
def test_held_out_orientations_inside_the_bands(family, family_cases):
    c1, c2 = _family_coverage(family_cases[family])["held_out"]
    assert within_bands(c1, c2, tol=FAMILY_BAND_TOL), (family, c1, c2)


def test_ward_hemispheres_are_not_overconfident(family_cases):
    """The hemispheres are over-covered at 1σ (a recorded miss), never under-covered."""
    cov = _family_coverage(family_cases["ward"])
    for case in ("hemi90", "hemi45"):
        c1, c2 = cov[case]
        assert c1 >= 0.60 - FAMILY_BAND_TOL and c2 >= 0.90 - FAMILY_BAND_TOL, (case, c1, c2)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_rescaled_sigma_leaves_the_bands(factor, family_cases):
    """The band check can fail: σ halved or doubled takes a family's held-out orientations
    out of the bands."""
    for fam, rows in family_cases.items():
        c1, c2 = _family_coverage(rows, factor)["held_out"]
        assert not within_bands(c1, c2, tol=FAMILY_BAND_TOL), (fam, factor, c1, c2)


def test_frozen_scales_are_the_calibrated_ones(ward_file):
    """KES_SIGMA_SCALES are the grid point bench_calibrate_sigma.py chose on all five
    families (2026-12-03; a change must come with a new calibration run), and each scale
    acts on its own term: a larger azimuth scale widens σ between orientations only, a
    larger slice scale off the slice only."""
    assert KES_SIGMA_SCALES == {"azimuth": 1.0, "azimuth_power": 1.0, "slice": 0.3, "slice_misfit": 3.0}
    model, _ = ward_file
    wi, wr = _pairs()
    base = predict_kes_sigma(model, wi, wr)[2][:, 0]
    wide_az = predict_kes_sigma(model, wi, wr, {"azimuth": 2.0})[2][:, 0]
    wide_sl = predict_kes_sigma(model, wi, wr, {"slice": 0.6})[2][:, 0]
    assert wide_az[1] > base[1] and np.allclose(wide_az[[0, 2]], base[[0, 2]])
    assert np.all(wide_sl[3:] > base[3:]) and np.allclose(wide_sl[:3], base[:3])
