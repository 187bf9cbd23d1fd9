"""Fixtures for the plotting tests: a small fitted model on the Agg backend."""

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
pytest.importorskip("matplotlib")


@pytest.fixture(scope="session")
def satin_ref():
    """Satin-like anisotropic Ward (narrow along the warp), one channel."""
    from kesbrdf.references.ward import AnisotropicWard

    return AnisotropicWard(alpha_x=0.08, alpha_y=0.22, rho_d=0.02, rho_s=0.12)


@pytest.fixture(scope="session")
def satin_measurement(satin_ref):
    """The paper's protocol (116 samples) on the satin reference, no noise."""
    from kesbrdf.gonio import measure

    m = measure(satin_ref)
    m.sha256 = "0" * 63 + "1"  # a recognisable stand-in hash for provenance checks
    return m


@pytest.fixture(scope="session")
def satin_model(satin_measurement):
    from kesbrdf.model import fit

    return fit(satin_measurement)


@pytest.fixture(scope="session")
def rgb_model():
    """A three-channel model (for channel selection)."""
    from kesbrdf.gonio import measure
    from kesbrdf.model import fit
    from kesbrdf.references.ward import AnisotropicWard

    return fit(measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1)))


@pytest.fixture
def fig():
    from kesbrdf.plotting._mpl import new_figure

    return new_figure()

