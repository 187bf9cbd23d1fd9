"""Sensor model: its noise matches its own prediction, it clips, it encodes sRGB."""

import numpy as np
import pytest

from kesbrdf.measure.acquisition.sensor import Sensor, srgb_decode, srgb_encode, vignetting_map
from kesbrdf.errors import KesbrdfError

#: Pixels in the flat test frames; the sample std of n Gaussian values has a relative
#: standard error 1/sqrt(2n) = 0.35 % at n = 40 000, so 3 % is more than 8 of them.
N_SIDE = 200
STD_RTOL = 0.03


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_noise_matches_predicted_pixel_sigma(rng, bit_depth):
    sensor = Sensor(bit_depth=bit_depth)
    exposure_s, rate = 0.5, 12000.0  # 6000 e-: a fifth of the full well
    frame = sensor.expose(np.full((N_SIDE, N_SIDE, 1), rate), exposure_s, rng).astype(float)
    predicted = sensor.pixel_sigma_dn(rate * exposure_s, exposure_s)
    assert frame.std() == pytest.approx(predicted, rel=STD_RTOL)
    # the mean is the expected signal above the black level (dark current included)
    signal_e = (rate + sensor.dark_current_e_per_s) * exposure_s
    mean_tol = 5 * predicted / N_SIDE + 0.5  # 5 standard errors + rounding
    assert abs(frame.mean() - sensor.black_level - signal_e / sensor.gain_e_per_dn) < mean_tol


def test_full_well_reads_the_largest_code(rng):
    sensor = Sensor(bit_depth=16)
    frame = sensor.expose(np.full((8, 8, 3), 1e9), 1.0, rng)
    assert frame.dtype == np.uint16
    assert np.all(frame == 65535)


def test_dark_frame_sits_at_the_black_level(rng):
    sensor = Sensor(bit_depth=16)
    frame = sensor.expose(np.zeros((100, 100, 1)), 0.01, rng).astype(float)
    assert frame.mean() == pytest.approx(sensor.black_level, abs=0.1)


def test_vignetting_darkens_corners_only(rng):
    v = vignetting_map(9, 9, 0.3)
    assert v[4, 4] == pytest.approx(1.0)
    assert v[0, 0] == pytest.approx(0.7)
    sensor = Sensor(vignetting=0.3, read_noise_e=0.0, dark_current_e_per_s=0.0)
    frame = sensor.expose(np.full((9, 9, 1), 1e4), 1.0, rng).astype(float) - sensor.black_level
    assert frame[0, 0, 0] / frame[4, 4, 0] == pytest.approx(0.7, rel=0.05)  # shot noise ~1 %


def test_srgb_round_trip():
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(srgb_decode(srgb_encode(x)), x, atol=1e-12)
    assert float(srgb_encode(0.0031308)) == pytest.approx(12.92 * 0.0031308)


def test_srgb_response_stores_encoded_codes(rng):
    sensor = Sensor(bit_depth=8, response="srgb", read_noise_e=0.0, dark_current_e_per_s=0.0, black_level_dn=0)
    frame = sensor.expose(np.full((50, 50, 1), sensor.full_well_e * 0.2), 1.0, rng).astype(float)
    # 20 % linear encodes to 48.4 % of the code range
    assert frame.mean() / 255 == pytest.approx(float(srgb_encode(0.2)), abs=0.01)


@pytest.mark.parametrize(
    "kwargs",
    [dict(bit_depth=12), dict(response="log"), dict(full_well_e=0), dict(vignetting=1.5), dict(black_level_dn=70000)],
)
def test_bad_parameters_are_refused(kwargs):
    with pytest.raises(KesbrdfError):
        Sensor(**kwargs)
