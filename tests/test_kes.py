"""Extended KES (paper eq. 1–2) and its 4-orientation form against hand computation."""

import numpy as np
import pytest

from kesbrdf.models import interpolation as kes

#: Pure float arithmetic on O(1) numbers: agreement to a few ulps.
ROUND_OFF = 1e-12


def test_eq1_2_equals_hand_computation():
    # ρ(0)=2, ρ(45)=4, ρ(90)=1 → K0=0.5, K45=0.25, K90=1; G' = 4·0.25 − 0.5 − 1 = −0.5
    # at φ = 30°: c² = 3/4, s² = 1/4 → K = 0.5·9/16 − 0.5·3/16 + 1·1/16 = 0.25
    K = kes.kes3(0.5, 0.25, 1.0, np.radians(30.0))
    assert K == pytest.approx(0.25, abs=ROUND_OFF)


def test_4_orientation_form_equals_hand_computation():
    # K0=1, K45=2, K90=3, K135=5: B = 2(2+5) − 1 − 3 = 10, D = 2 − 5 = −3
    # at φ = 60°: c = 1/2, s = √3/2: K = 1/16 + 10·3/16 + 3·9/16 − 3·√3/4
    expected = 1 / 16 + 30 / 16 + 27 / 16 - 3 * np.sqrt(3) / 4
    assert kes.kes4(1.0, 2.0, 3.0, 5.0, np.radians(60.0)) == pytest.approx(expected, abs=ROUND_OFF)


@pytest.mark.parametrize("form", ["kes3", "kes4"])
def test_kes_passes_through_measured_orientations(form):
    K = {0: 0.7, 45: 1.9, 90: 3.1, 135: 1.3}
    for deg, value in K.items():
        if form == "kes3":
            if deg == 135:
                continue
            got = kes.kes3(K[0], K[45], K[90], np.radians(deg))
        else:
            got = kes.kes4(K[0], K[45], K[90], K[135], np.radians(deg))
        assert got == pytest.approx(value, abs=ROUND_OFF)


def test_kes4_reduces_to_kes3_when_biases_agree(rng):
    phi = rng.uniform(0, 2 * np.pi, 50)
    np.testing.assert_allclose(kes.kes4(1.0, 2.0, 3.0, 2.0, phi), kes.kes3(1.0, 2.0, 3.0, phi), atol=ROUND_OFF)


def test_kes3_is_symmetric_under_phi_to_pi_minus_phi(rng):
    phi = rng.uniform(0, np.pi, 50)
    np.testing.assert_allclose(kes.kes3(1.0, 2.5, 3.0, phi), kes.kes3(1.0, 2.5, 3.0, np.pi - phi), atol=ROUND_OFF)


def test_whole_circle_passes_through_all_eight_half_samples(rng):
    K_half = rng.uniform(0.5, 3.0, size=(5, 8))
    got = kes.interpolate_circle(K_half, kes.HALF_AZIMUTHS)
    np.testing.assert_allclose(got, K_half, rtol=ROUND_OFF)


def test_whole_circle_even_part_is_the_4_orientation_form(rng):
    K_half = rng.uniform(0.5, 3.0, size=8)
    phi = rng.uniform(0, 2 * np.pi, 40)
    even = 0.5 * (kes.interpolate_circle(K_half, phi) + kes.interpolate_circle(K_half, phi + np.pi))
    e = 0.5 * (K_half[:4] + K_half[4:])
    np.testing.assert_allclose(even, kes.kes4(e[0], e[1], e[2], e[3], phi), rtol=1e-10)


def test_whole_circle_equals_paper_form_when_halves_agree(rng):
    K4 = rng.uniform(0.5, 3.0, size=4)
    K_half = np.concatenate([K4, K4])
    phi = rng.uniform(0, 2 * np.pi, 40)
    np.testing.assert_allclose(kes.interpolate_circle(K_half, phi), kes.kes4(*K4, phi), rtol=1e-10)
    K_half[[3, 7]] = np.nan  # ignored with three orientations
    np.testing.assert_allclose(
        kes.interpolate_circle(K_half, phi, orientations=3), kes.kes3(K4[0], K4[1], K4[2], phi), rtol=1e-10
    )


def test_whole_circle_is_continuous_and_periodic(rng):
    K_half = rng.uniform(0.5, 3.0, size=8)
    phi = np.linspace(0, 2 * np.pi, 2001)
    K = kes.interpolate_circle(K_half, phi)
    assert K[0] == pytest.approx(K[-1], rel=1e-12)
    assert np.max(np.abs(np.diff(K))) < 0.05  # smooth: no jump at 0 or π


def test_log_fallback_passes_through_and_stays_positive(rng):
    q_half = rng.uniform(1e-3, 2.0, size=8)
    phi = np.linspace(0, 2 * np.pi, 721)
    q = kes.interpolate_circle_log(q_half, phi)
    assert np.all(q > 0)
    np.testing.assert_allclose(kes.interpolate_circle_log(q_half, kes.HALF_AZIMUTHS), q_half, rtol=1e-12)


def test_kes_can_go_negative_between_orientations():
    # warp and weft very different: the quartic dips below zero between them (docs/method.md, "Interpolation over orientation")
    K = kes.kes3(1.0, 0.1, 50.0, np.radians(np.arange(0, 91)))
    assert K.min() < 0


def test_bad_orientation_count():
    from kesbrdf.errors import KESError

    with pytest.raises(KESError, match="orientations 3 or 4"):
        kes.circle_basis(0.0, orientations=5)
