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


# Hypothesis profiles: "default" for the suite (derandomized, so a run is repeatable),
# "fuzz" for `make fuzz` (HYPOTHESIS_PROFILE=fuzz): 100,000 examples per property.
# Fuzz tests take their example count from tests/mutations.py::examples();
# KESBRDF_FUZZ_EXAMPLES=N changes the fuzz profile's count (a shorter sweep).
try:
    from hypothesis import HealthCheck, settings
except ImportError:  # pragma: no cover - hypothesis is in the test extra
    pass
else:
    _quiet = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
    settings.register_profile("default", deadline=None, derandomize=True, suppress_health_check=_quiet)
    settings.register_profile(
        "fuzz",
        max_examples=int(os.environ.get("KESBRDF_FUZZ_EXAMPLES", "100000")),
        deadline=None,
        suppress_health_check=_quiet,
        database=None,
    )
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
