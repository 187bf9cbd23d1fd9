import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session", autouse=True)
def _private_fit_cache(tmp_path_factory):
    """Analytic-fit cache of the test session in its own folder, never the user's
    ~/.cache/kesbrdf (kesbrdf.export.fit_cache); tests that count fits set their own."""
    old = os.environ.get("KESBRDF_CACHE_DIR")
    os.environ["KESBRDF_CACHE_DIR"] = str(tmp_path_factory.mktemp("fit-cache"))
    yield
    if old is None:
        os.environ.pop("KESBRDF_CACHE_DIR", None)
    else:
        os.environ["KESBRDF_CACHE_DIR"] = old


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


# -- fixtures shared by a library folder and its CLI tests (tests/cli/) --------------------
# acquisition: a known BRDF and a small simulated rig
@pytest.fixture
def lambertian_rgb():
    from acq_helpers import Lambertian

    return Lambertian([0.2, 0.5, 0.8])


@pytest.fixture
def small_rig(tmp_path, lambertian_rgb):
    """Frames + manifest of a Lambertian sample in a small rig; returns the manifest path."""
    from acq_helpers import SMALL_RIG

    from kesbrdf.measure.acquisition.camera import simulate_images

    return simulate_images(lambertian_rgb, tmp_path / "rig", seed=7, **SMALL_RIG)


# plotting: a satin-like reference, its paper-protocol measurement and model
@pytest.fixture(scope="session")
def satin_ref():
    """Satin-like anisotropic Ward (narrow along the warp), one channel."""
    from kesbrdf.references.ward import AnisotropicWard

    return AnisotropicWard(alpha_x=0.08, alpha_y=0.22, rho_d=0.02, rho_s=0.12)


@pytest.fixture(scope="session")
def satin_measurement(satin_ref):
    """The paper's protocol (116 samples) on the satin reference, no noise."""
    from kesbrdf.measure.gonio import measure

    m = measure(satin_ref)
    m.sha256 = "0" * 63 + "1"  # a recognisable stand-in hash for provenance checks
    return m


@pytest.fixture(scope="session")
def satin_model(satin_measurement):
    from kesbrdf.models.kes import fit

    return fit(satin_measurement)


# the fibre-coord kind: one quick fit shared by its model and plugin tests
@pytest.fixture(scope="session")
def fibre_coord_fit():
    """(measurement, model): a fibre-coord fit to the Irawan silk charmeuse, paper protocol
    at 6° steps (56 samples, noise 2 %): filament/filament prior, KES residual."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.base import kind_class
    from kesbrdf.references.irawan2012 import Irawan2012

    m = measure(Irawan2012("silk_charmeuse"), protocol="paper", step_deg=6, noise=0.02, rng=3)
    return m, kind_class("fibre-coord").fit_measurement(m)


# rendering: small model files fitted from reference BRDFs
def _fit_and_save(path, ref, **fit_kwargs):
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    model = fit(measure(ref), **fit_kwargs)
    model.save(path)
    return path, model


@pytest.fixture(scope="session")
def render_module():
    """kesbrdf.render (registers the BSDF); skips the test when Mitsuba is not installed."""
    import importlib.util

    for name in ("mitsuba", "drjit"):
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            pytest.skip(f"render tests need {name} (install kesbrdf[render])")
    import kesbrdf.render

    return kesbrdf.render


@pytest.fixture(scope="session")
def model_files(tmp_path_factory):
    """Model files (path, Model) fitted on the paper protocol from anisotropic Ward."""
    from kesbrdf.references.ward import AnisotropicWard

    root = tmp_path_factory.mktemp("models")
    out = {}
    # RGB, lobe 3x wider along the weft than along the warp
    out["rgb"] = _fit_and_save(root / "rgb.kes.json", AnisotropicWard(0.1, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.1))
    # grey, strongly anisotropic: for the UV-rotation test
    out["aniso"] = _fit_and_save(root / "aniso.kes.json", AnisotropicWard(0.06, 0.35, rho_d=0.05, rho_s=0.15))
    # grey, albedo below one everywhere: for the white furnace
    out["furnace"] = _fit_and_save(root / "furnace.kes.json", AnisotropicWard(0.15, 0.3, rho_d=0.5, rho_s=0.2))
    # RGB over a Fresnel-weighted body (GGX reference): the table carries a body law (eq. B3)
    from kesbrdf.references.ggx import AnisotropicGGX

    out["law"] = _fit_and_save(root / "law.kes.json", AnisotropicGGX(0.15, 0.3, eta=1.5, rho_d=[0.5, 0.3, 0.2], k_s=0.6))
    assert out["law"][1].body_law is not None
    return out


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
