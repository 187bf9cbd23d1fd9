"""The virtual gonioreflectometer camera: frames, manifest, exposure, determinism."""

import numpy as np
import pytest

from kesbrdf.measure.acquisition.camera import EXPOSURE_LADDER_S, simulate_images
from kesbrdf.measure.acquisition.images import read_image
from kesbrdf.measure.acquisition.manifest import read_manifest
from kesbrdf.measure.acquisition.sensor import Sensor
from kesbrdf.errors import KesbrdfError

from acq_helpers import SMALL_RIG, Lambertian


def test_paper_protocol_writes_4x29_samples_whites_and_darks(tmp_path, lambertian_rgb):
    path = simulate_images(lambertian_rgb, tmp_path, protocol="paper", size=8, margin=1, roi_inset=1)
    m = read_manifest(path)
    samples, whites, darks = (m.of_kind(k) for k in ("sample", "white", "dark"))
    assert len(samples) == 4 * 29
    assert len(whites) == 29
    assert sorted({r.psi_deg for r in samples}) == [0, 45, 90, 135]
    assert all(r.theta_i_deg + r.theta_r_deg == pytest.approx(90) for r in samples)
    # one dark frame per exposure used, and every exposure from the ladder
    used = {r.exposure_s for r in samples + whites}
    assert {r.exposure_s for r in darks} == used
    assert used <= set(EXPOSURE_LADDER_S.tolist())
    assert m.white_reflectance == 0.99 and m.header["simulated"] == "true"
    assert all(r.path.is_file() for r in m.rows)


def test_frames_are_deterministic_for_a_seed(tmp_path, lambertian_rgb):
    a = simulate_images(lambertian_rgb, tmp_path / "a", seed=3, **SMALL_RIG)
    b = simulate_images(lambertian_rgb, tmp_path / "b", seed=3, **SMALL_RIG)
    c = simulate_images(lambertian_rgb, tmp_path / "c", seed=4, **SMALL_RIG)
    name = read_manifest(a).of_kind("sample")[0].file
    pa, pb, pc = (read_image(p.parent / name).pixels for p in (a, b, c))
    np.testing.assert_array_equal(pa, pb)
    assert not np.array_equal(pa, pc)


def test_frame_shows_sample_on_black_mount(tmp_path, lambertian_rgb):
    path = simulate_images(lambertian_rgb, tmp_path, **SMALL_RIG)
    m = read_manifest(path)
    row = m.of_kind("sample")[0]
    pixels = read_image(row.path).pixels
    black = Sensor().black_level
    x0, y0, x1, y1 = row.roi
    assert row.roi == (3, 3, 9, 9)  # margin 2 + inset 1 in a 12-pixel frame
    assert pixels[y0:y1, x0:x1].mean() > black + 1000  # lit sample
    assert abs(pixels[0].mean() - black) < 10  # mount: dark only


def test_auto_exposure_stays_below_target(tmp_path, lambertian_rgb):
    path = simulate_images(lambertian_rgb, tmp_path, auto_target=0.5, **SMALL_RIG)
    sensor = Sensor()
    for row in read_manifest(path).of_kind("sample"):
        peak = read_image(row.path).pixels.max()
        assert peak < sensor.black_level + 0.6 * (sensor.max_code - sensor.black_level)


def test_fixed_long_exposure_clips(tmp_path, lambertian_rgb):
    path = simulate_images(lambertian_rgb, tmp_path, exposure=10.0, **SMALL_RIG)
    row = read_manifest(path).of_kind("sample")[0]
    assert read_image(row.path).pixels.max() == 65535


def test_sparse_whites_and_exr_output(tmp_path):
    path = simulate_images(
        Lambertian(0.5), tmp_path, protocol="paper", step_deg=10, whites="sparse", file_format="exr",
        size=8, margin=1, roi_inset=1,
    )
    m = read_manifest(path)
    assert 1 < len(m.of_kind("white")) < 8
    assert m.saturation_level == 1.0
    frame = read_image(m.of_kind("sample")[0].path)
    assert frame.dtype == "float32" and frame.shape == (8, 8, 1)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(whites="some"), "whites: expected one of"),
        (dict(file_format="jpeg"), "file_format: expected one of"),
        (dict(file_format="png"), "16-bit colour frames cannot be PNG"),
        (dict(exposure=-1.0), "exposure: expected 'auto' or seconds > 0"),
        (dict(size=4), "expected size >= 4 with room for the ROI"),
    ],
)
def test_bad_settings_are_refused(tmp_path, lambertian_rgb, kwargs, message):
    settings = {**SMALL_RIG, **kwargs}
    with pytest.raises(KesbrdfError, match=message):
        simulate_images(lambertian_rgb, tmp_path, **settings)
