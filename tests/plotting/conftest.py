"""Fixtures for the plotting tests: a small fitted model on the Agg backend."""

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
pytest.importorskip("matplotlib")


@pytest.fixture(scope="session")
def rgb_model():
    """A three-channel model (for channel selection)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    return fit(measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1)))


@pytest.fixture
def fig():
    from kesbrdf.plotting._mpl import new_figure

    return new_figure()

