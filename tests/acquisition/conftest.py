"""Fixtures of the acquisition tests: a known BRDF and a small simulated rig."""

import pytest
from acq_helpers import SMALL_RIG, Lambertian


@pytest.fixture
def lambertian_rgb():
    return Lambertian([0.2, 0.5, 0.8])


@pytest.fixture
def small_rig(tmp_path, lambertian_rgb):
    """Frames + manifest of a Lambertian sample in a small rig; returns the manifest path."""
    from kesbrdf.acquisition.camera import simulate_images

    return simulate_images(lambertian_rgb, tmp_path / "rig", seed=7, **SMALL_RIG)
