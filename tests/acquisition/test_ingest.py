"""Ingest: known patch values come back within the noise the sensor model predicts."""

import json
import math

import numpy as np
import pytest
from acq_helpers import Lambertian, edit_manifest, exposures, predicted_sigma

from kesbrdf.measure.acquisition.camera import simulate_images
from kesbrdf.measure.acquisition.images import read_image, sha256_file, write_image
from kesbrdf.measure.acquisition.ingest import IngestError, ingest, robust_mean
from kesbrdf.measure.acquisition.sensor import Sensor
from kesbrdf.errors import KesbrdfError

#: Every ingested value lies within this many predicted standard deviations of the
#: truth.  For Gaussian errors P(|z| > 4.5) = 6.8e-6, so with ~100 values a correct
#: ingest fails this by chance with probability < 1e-3; a bias of one σ would not pass
#: the mean-z² check below.
Z_MAX = 4.5
#: Mean of z² over ~100 values: expected 1 with a standard error of sqrt(2/100) = 0.14;
#: [0.5, 1.6] is more than 3.5 standard errors on each side.
MEAN_Z2_RANGE = (0.5, 1.6)
#: Reported uncertainty vs the sensor-model prediction: the sample std of the ~200
#: kept ROI pixels has a relative standard error 1/sqrt(2·200) = 5 %; 25 % is 5 of them.
UNC_RTOL = 0.25
#: A 14 × 14 ROI (size 24, margin 3, inset 2): 196 pixels per value.
RIG = dict(protocol="paper", step_deg=10.0, size=24, margin=3, roi_inset=2)
N_ROI = 14 * 14


def _truth(brdf, m):
    return brdf(m.wi, m.wr)


@pytest.mark.parametrize("bit_depth", [16, 8])
def test_recovers_known_values_within_predicted_noise(tmp_path, lambertian_rgb, bit_depth):
    sensor = Sensor(bit_depth=bit_depth)
    result = ingest(simulate_images(lambertian_rgb, tmp_path, sensor=sensor, seed=11, **RIG))
    m = result.measurement
    assert len(m) == 4 * 8 and m.channels == ("R", "G", "B")
    t_s, t_w = exposures(result)
    sigma = predicted_sigma(sensor, _truth(lambertian_rgb, m), m.theta_i, t_s, t_w, N_ROI)
    z = (m.values - _truth(lambertian_rgb, m)) / sigma
    assert np.abs(z).max() < Z_MAX
    assert MEAN_Z2_RANGE[0] < np.mean(z**2) < MEAN_Z2_RANGE[1]
    np.testing.assert_allclose(m.uncertainty, sigma, rtol=UNC_RTOL)
    assert result.counts()["rejected"] == 0 and set(m.provenance["flag"]) == {"ok"}


def test_srgb_encoded_8bit_frames_are_linearised(tmp_path, lambertian_rgb):
    sensor = Sensor(bit_depth=8, response="srgb")
    m = ingest(simulate_images(lambertian_rgb, tmp_path, sensor=sensor, seed=12, **RIG)).measurement
    # Without linearisation the values would be off by tens of percent; with it, what
    # is left is the noise (σ ≈ 0.3 % here) and the rounding of the encoded codes,
    # whose bias after averaging is well below 1 %.
    np.testing.assert_allclose(m.values, _truth(lambertian_rgb, m), rtol=0.01)


def test_vignetting_cancels_against_the_white(tmp_path, lambertian_rgb):
    sensor = Sensor(vignetting=0.3)
    m = ingest(simulate_images(lambertian_rgb, tmp_path, sensor=sensor, seed=13, **RIG)).measurement
    # Sample and white share the vignetting pattern: the ratio of ROI means is unbiased.
    # The reported uncertainty now also holds the vignetting spread, so it is the bound.
    z = (m.values - _truth(lambertian_rgb, m)) / m.uncertainty
    assert np.abs(z).max() < Z_MAX


def test_cosine_model_of_the_white_where_no_white_frame(tmp_path, lambertian_rgb):
    result = ingest(simulate_images(lambertian_rgb, tmp_path, whites="sparse", seed=14, **RIG))
    m = result.measurement
    details = [r.detail for r in result.summary if r.kind == "sample"]
    assert any("cosine model of the white" in d for d in details)
    assert any("white at same geometry" in d for d in details)
    # The virtual white is an ideal Lambertian, so the model is exact: noise only.
    # The reported uncertainty carries the noise of the white actually used.
    z = (m.values - _truth(lambertian_rgb, m)) / m.uncertainty
    assert np.abs(z).max() < Z_MAX


def test_clipped_frames_become_lower_bounds_when_asked(tmp_path, lambertian_rgb):
    manifest = simulate_images(lambertian_rgb, tmp_path, exposure=0.6, seed=15, **RIG)
    with pytest.raises(IngestError, match="ROI pixels clipped") as info:
        ingest(manifest)
    rejected = [r for r in info.value.summary if r.status == "rejected"]
    assert rejected and all("clipped" in r.detail for r in rejected)
    result = ingest(manifest, saturation="lower_bound")
    m = result.measurement
    flags = np.array(m.provenance["flag"])
    assert "lower_bound" in flags and "ok" in flags
    clipped = flags == "lower_bound"
    # clipping only removes signal: a lower bound (allowing 4.5 σ of noise above)
    assert np.all(m.values[clipped] < _truth(lambertian_rgb, m)[clipped] + Z_MAX * m.uncertainty[clipped])
    assert np.any(m.values[clipped] < 0.9 * _truth(lambertian_rgb, m)[clipped])
    assert any("lower bound" in n for n in m.notes)


def test_negative_value_within_noise_is_flagged_not_rejected(tmp_path):
    brdf = Lambertian([0.0, 0.5, 0.5])  # channel R has no signal at all
    m = ingest(simulate_images(brdf, tmp_path, seed=16, **RIG)).measurement
    r = m.values[:, 0]
    assert np.all(np.abs(r) < Z_MAX * m.uncertainty[:, 0])  # consistent with zero
    flags = np.array(m.provenance["flag"])
    assert np.any(r < 0)
    assert np.all(flags[r < 0] == "flagged") and np.all(flags[r >= 0] == "ok")


def test_significantly_negative_value_is_rejected(small_rig):
    row = next(r for r in small_rig.read_text().splitlines() if ",sample," in r)
    frame_path = small_rig.parent / row.split(",")[0]
    write_image(frame_path, np.full((12, 12, 3), 100, np.uint16))  # below the 1024 DN black level
    with pytest.raises(IngestError, match=r"value negative after dark subtraction: -9\d\d"):
        ingest(small_rig)


def test_all_problems_are_counted(small_rig):
    def drop(rows):
        for r in rows[:]:
            if r["kind"] == "sample":
                r["file"] = "missing_" + r["file"]
        return rows

    edit_manifest(small_rig, drop)
    with pytest.raises(IngestError, match=r"file not found .* \(7 more problems in other frames\)") as info:
        ingest(small_rig)
    assert sum(r.status == "rejected" for r in info.value.summary) == 8


def test_provenance_and_metadata(small_rig):
    m = ingest(small_rig).measurement
    assert all(f.startswith("sample_") for f in m.provenance["file"])
    first = small_rig.parent / m.provenance["file"][0]
    assert m.provenance["file_sha256"][0] == sha256_file(first)
    acquisition = json.loads(m.metadata["acquisition"])
    assert acquisition["manifest_sha256"] == sha256_file(small_rig)
    assert acquisition["white_reflectance"] == 0.99
    assert m.metadata["simulated"] == "true" and m.metadata["quantity"] == "brdf"
    assert np.allclose(np.degrees(m.psi[:2]), 0.0) and m.is_in_plane.all()


def test_general_geometry_rows(small_rig, lambertian_rgb):
    def add_azimuths(rows):
        for r in rows:
            if r["kind"] == "sample":
                r["phi_i_deg"], r["phi_r_deg"] = str(float(r["psi_deg"]) + 180 + 10), str(float(r["psi_deg"]) + 10)
                r["psi_deg"] = ""
        return rows

    edit_manifest(small_rig, add_azimuths, add_columns=("phi_i_deg", "phi_r_deg"))
    m = ingest(small_rig).measurement
    assert not m.is_in_plane.any()
    assert np.degrees(m.phi_r[0]) == pytest.approx(10.0)
    np.testing.assert_allclose(m.values, _truth(lambertian_rgb, m), rtol=0.01)


def test_robust_mean_ignores_hot_pixels(rng):
    x = rng.normal(100.0, 2.0, size=(400, 1))
    x[:5] = 60000.0  # hot pixels / specks
    centre, unc, n = robust_mean(x)
    assert n[0] == 395
    # 4 standard errors of a mean of 395 values with σ = 2
    assert abs(centre[0] - 100.0) < 4 * 2.0 / math.sqrt(395)
    assert unc[0] == pytest.approx(2.0 / math.sqrt(395), rel=0.15)


def test_robust_mean_on_constant_codes_with_a_hot_pixel():
    # MAD = 0 and the only non-zero distance is the hot pixel: it must not set the window
    x = np.concatenate([np.full(99, 10.0), [1e6]])[:, None]
    centre, unc, n = robust_mean(x)
    assert (centre[0], unc[0], n[0]) == (10.0, 0.0, 99)


def test_robust_mean_keeps_quantised_noise(rng):
    # σ = 0.6 code: MAD is 0 or 1 code; the window must still keep every noise pixel
    x = np.rint(rng.normal(50.0, 0.6, size=(2000, 1)))
    centre, unc, n = robust_mean(x)
    assert n[0] == 2000
    assert unc[0] * np.sqrt(2000) == pytest.approx(x.std(ddof=1), rel=1e-9)


def test_unknown_saturation_mode(small_rig):
    with pytest.raises(KesbrdfError, match="saturation: expected one of reject, lower_bound"):
        ingest(small_rig, saturation="clip")


def test_progress_is_reported(small_rig):
    calls = []
    ingest(small_rig, progress=lambda done, total, file: calls.append((done, total)))
    assert calls[-1][0] == calls[-1][1] == len(calls)


def test_frame_pixels_are_read_once_per_row(small_rig):
    # the measurement keeps one row per sample frame, in manifest order
    m = ingest(small_rig).measurement
    assert len(m) == 8
    assert read_image(small_rig.parent / m.provenance["file"][0]).shape == (12, 12, 3)


def test_rows_without_roi_use_the_whole_frame(tmp_path, lambertian_rgb):
    manifest = simulate_images(lambertian_rgb, tmp_path, protocol="paper", step_deg=30.0, size=10, margin=0, roi_inset=0)

    def drop_roi(rows):
        for r in rows:
            r["roi"] = ""
        return rows

    edit_manifest(manifest, drop_roi)
    m = ingest(manifest).measurement
    # 100 pixels per frame at half the full well: σ/f ≈ 0.1 %; 1 % is 10 σ
    np.testing.assert_allclose(m.values, _truth(lambertian_rgb, m), rtol=0.01)


@pytest.mark.parametrize(
    "brdf, file_format, bit_depth",
    [(Lambertian([0.2, 0.5, 0.8]), "exr", 16), (Lambertian(0.4), "png", 8), (Lambertian(0.4), "png", 16)],
)
def test_every_image_format_calibrates(tmp_path, brdf, file_format, bit_depth):
    sensor = Sensor(bit_depth=bit_depth)
    result = ingest(simulate_images(brdf, tmp_path, sensor=sensor, file_format=file_format, seed=17, **RIG))
    m = result.measurement
    assert m.channels == (("value",) if brdf.rho.size == 1 else ("R", "G", "B"))
    t_s, t_w = exposures(result)
    sigma = predicted_sigma(sensor, _truth(brdf, m), m.theta_i, t_s, t_w, N_ROI)
    assert np.abs((m.values - _truth(brdf, m)) / sigma).max() < Z_MAX


def test_clipped_exr_frames_are_detected(tmp_path, lambertian_rgb):
    manifest = simulate_images(lambertian_rgb, tmp_path, file_format="exr", exposure=0.6, seed=18, **RIG)
    with pytest.raises(IngestError, match=r"ROI pixels clipped \(at or above code 1\)"):
        ingest(manifest)
