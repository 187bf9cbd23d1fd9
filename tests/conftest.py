import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def rng():
    """The only source of randomness in tests (seeded)."""
    return np.random.default_rng(20261122)


@pytest.fixture
def ward():
    """Moderately anisotropic reference (lobe 2x longer along the weft)."""
    from kesbrdf.references.ward import AnisotropicWard

    return AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1)


@pytest.fixture
def random_pairs(rng):
    from kesbrdf.geometry import spherical_to_cartesian

    n = 2000
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(0, 2 * np.pi, n))
    return wi, wr
