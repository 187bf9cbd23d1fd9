"""kesbrdf.measure.measurement: the in-plane construction (docs/method.md, "Conventions"), shapes, views and subsets."""

import numpy as np
import pytest

from kesbrdf.errors import MeasurementError
from kesbrdf.measure.measurement import PAPER_ORIENTATIONS, PAPER_ORIENTATIONS_DEG, Measurement

#: Directions built from angles: rounding of sin/cos only.
DIRECTION_ATOL = 1e-12


def test_paper_orientations_are_warp_bias_weft_bias():
    assert PAPER_ORIENTATIONS_DEG == (0.0, 45.0, 90.0, 135.0)
    np.testing.assert_allclose(PAPER_ORIENTATIONS, np.radians(PAPER_ORIENTATIONS_DEG), rtol=0, atol=0)


def test_in_plane_puts_the_light_opposite_the_viewer_in_the_plane_of_psi():
    psi = np.radians([0.0, 45.0, 90.0, 135.0])
    m = Measurement.in_plane(psi, np.radians(60.0), np.radians(30.0), values=np.ones(4))
    wi, wr = m.wi, m.wr
    # horizontal components antiparallel and along (cos psi, sin psi); polar angles kept
    np.testing.assert_allclose(wr[:, :2] / np.linalg.norm(wr[:, :2], axis=1, keepdims=True),
                               np.stack([np.cos(psi), np.sin(psi)], -1), atol=DIRECTION_ATOL)
    np.testing.assert_allclose(wi[:, :2] / np.linalg.norm(wi[:, :2], axis=1, keepdims=True),
                               -np.stack([np.cos(psi), np.sin(psi)], -1), atol=DIRECTION_ATOL)
    np.testing.assert_allclose(wi[:, 2], np.cos(np.radians(60.0)), atol=DIRECTION_ATOL)
    np.testing.assert_allclose(wr[:, 2], np.cos(np.radians(30.0)), atol=DIRECTION_ATOL)
    np.testing.assert_allclose(m.gamma, np.radians(-30.0), atol=DIRECTION_ATOL)
    assert m.is_in_plane.all()
    np.testing.assert_allclose(m.orientations(), psi, atol=1e-6)


def test_q_is_f_times_the_root_of_the_cosines():
    m = Measurement.in_plane(0.0, np.radians([0.0, 60.0]), np.radians([60.0, 60.0]), values=[2.0, 2.0])
    np.testing.assert_allclose(m.q[:, 0], 2.0 * np.sqrt(np.cos(np.radians([0.0, 60.0])) * 0.5), rtol=1e-15)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(values=np.ones((3, 2))), "expected values of shape (3, 1)"),
        (dict(values=np.ones(3), uncertainty=np.ones(2)), "expected uncertainty of shape (3, 1)"),
        (dict(values=np.ones(3), psi=np.zeros(2)), "expected 3 psi values"),
    ],
)
def test_inconsistent_shapes_are_measurement_errors(kwargs, message):
    with pytest.raises(MeasurementError) as info:
        Measurement(theta_i=np.zeros(3), phi_i=np.zeros(3), theta_r=np.zeros(3), phi_r=np.zeros(3), **kwargs)
    assert message in str(info.value)


def test_subset_keeps_rows_and_their_provenance():
    m = Measurement.in_plane(np.radians([0.0, 90.0, 45.0]), 0.5, 0.4, values=[1.0, 2.0, 3.0],
                             uncertainty=[0.1, 0.2, 0.3], provenance={"file": ["a", "b", "c"]})
    s = m.subset([True, False, True])
    assert len(s) == 2 and s.values[:, 0].tolist() == [1.0, 3.0]
    assert s.uncertainty[:, 0].tolist() == [0.1, 0.3] and s.provenance["file"] == ["a", "c"]
    assert len(m) == 3  # the original is untouched
