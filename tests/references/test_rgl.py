"""Tests of kesbrdf.references.rgl on the committed RGL-EPFL white acrylic felt, and the
end-to-end check tests/data/README asks for: an isotropic measured material, put
through the paper's protocol at four orientations and fitted, must come back at every
orientation.

All numbers below were measured on ``src/kesbrdf/data/rgl/acrylic_felt_white_rgb.bsdf``
(Mitsuba 3.9.1, variant llvm_ad_rgb); see the comment next to each constant.
"""

from __future__ import annotations


import numpy as np
import pytest

from kesbrdf.errors import FormatError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.references.rgl import RGLMeasured, read_tensor_file
from kesbrdf.references.registry import SHIPPED_RGL_DIR

FELT = SHIPPED_RGL_DIR / "acrylic_felt_white_rgb.bsdf"

# --- tolerances, each with where it comes from ---------------------------------------
#: Rotating both directions about the normal: Mitsuba evaluates the isotropic data in
#: float32 (φ_m − φ_i); measured max relative change 4e-5 over 20 000 random pairs.
ISOTROPY_RTOL = 1e-3
#: At the mirror direction the half vector is the normal and its azimuth is rounding
#: noise: in-plane values at γ = 0 change by up to 0.27 % between orientations (measured,
#: ψ = 0 vs 45°); everywhere else on the paper line by 0.
POLE_ANISOTROPY_RTOL = 5e-3
#: Measured reciprocity of the data, |f(i,r) − f(r,i)| / max, directions up to 80°
#: (20 000 random pairs): median 0.013, 95th percentile 0.083, max 0.74 (grazing).
RECIPROCITY_MEDIAN_MAX = 0.02
RECIPROCITY_P95_MAX = 0.10
#: The acquisition has no data where both directions are beyond about 78° near the
#: forward mirror direction: Mitsuba returns 0 there (0.13 % of random pairs up to 89°,
#: all with θ_i and θ_r > 77.7°, measured).  Below this polar angle every value is > 0.
POSITIVE_THETA_MAX_DEG = 75.0
#: Directional albedo measured 0.58–0.89 (θ_i = 0…80°, R < G < B); a white felt is
#: far from a perfect reflector, so the bound ≤ 1 has room and the lower bound catches
#: a lost factor π or cosine.
ALBEDO_MIN = 0.5
#: KES on a *reciprocal* isotropic felt (the felt averaged with its transpose):
#: held-out orientations reproduced to 0.10 % (measured); the residual is the pole
#: anisotropy above.
HELD_OUT_SYMMETRIC_RTOL = 2 * POLE_ANISOTROPY_RTOL
#: KES on the raw felt: the measurement is not reciprocal (0.114 max on the paper
#: line, at θ_i = 78°), so the +γ and −γ halves of each orientation differ and the
#: whole-circle interpolation (docs/method.md, "From the table to a BRDF") carries that difference as odd harmonics
#: between the orientations: held-out error measured 0.0200 (ψ = 112.5°, θ_i = 12°).
#: It must stay below the data's own non-reciprocity; the regression bound has a 25 %
#: margin.
HELD_OUT_RAW_MEASURED = 0.0200
REGRESSION_MARGIN = 1.25
#: Held-out orientations between the measured ones (ψ in degrees).
HELD_OUT_DEG = (22.5, 60.0, 112.5)
#: Fig. 6 hemispheres (light θ_i = 30°, φ_i = 90° and 45°), viewer to 87.5° in 2.5°
#: steps: measured RMSE (1/sr) and log-RMSE of each model against the felt
#: (mean f_r over the hemisphere 0.22/sr; a constant at that mean scores 0.0212 / 0.089).
HEMISPHERE_MEASURED = {
    # (kind, mapping): (rmse, log_rmse), worst of the two lights
    ("kes", "deviation"): (0.0195, 0.081),
    ("kes", "halfvector"): (0.0198, 0.083),
    ("kes", "paper"): (0.5453, 0.625),
    ("kes-halfdiff", "halfdiff"): (0.0293, 0.140),
}


def _mitsuba_available() -> bool:
    try:
        from kesbrdf.references.rgl import _import_mitsuba

        _import_mitsuba()
    except ImportError:
        return False
    return True


_skip_without_mitsuba = pytest.mark.skipif(not _mitsuba_available(), reason="mitsuba not installed (kesbrdf[render])")


def needs_mitsuba(test):
    """Mark a test ``render`` (needs mitsuba + libLLVM) and skip it without mitsuba."""
    return pytest.mark.render(_skip_without_mitsuba(test))


@pytest.fixture(scope="module")
def felt():
    """One evaluator for the module: the first evaluation compiles LLVM kernels."""
    if not _mitsuba_available():
        pytest.skip("mitsuba not installed (kesbrdf[render])")
    return RGLMeasured(FELT)


class _Symmetrised:
    """(f(i, r) + f(r, i)) / 2: the felt made exactly reciprocal."""

    channels = ("R", "G", "B")

    def __init__(self, f):
        self.f = f

    def __call__(self, wi, wr):
        return 0.5 * (self.f(wi, wr) + self.f(wr, wi))


def _upper(rng, n, theta_max_deg=80.0):
    """n directions uniform in solid angle on the cap θ ≤ theta_max_deg."""
    cos_theta = rng.uniform(np.cos(np.radians(theta_max_deg)), 1.0, n)
    return spherical_to_cartesian(np.arccos(cos_theta), rng.uniform(0, 2 * np.pi, n))


def _rotate_z(w, angle):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return w @ R.T


# --- the file reader (no Mitsuba needed) -----------------------------------------------
def test_tensor_file_fields_and_description():
    fields = read_tensor_file(FELT)
    assert bytes(fields["description"]).decode() == "White acrylic felt (Edukit A4)"
    assert fields["phi_i"].shape == (1,)  # isotropic
    np.testing.assert_allclose(np.degrees(fields["theta_i"][[0, -1]]), [0.0, 90.0], atol=1e-4)
    assert fields["rgb"].shape == (1, 8, 3, 32, 32)


def test_not_a_tensor_file_raises_with_path(tmp_path):
    bad = tmp_path / "felt.bsdf"
    bad.write_bytes(b"not a tensor file at all")
    with pytest.raises(FormatError, match="felt.bsdf: expected a Mitsuba tensor file"):
        read_tensor_file(bad)


def test_missing_file_raises_format_error(tmp_path):
    with pytest.raises(FormatError, match="missing.bsdf"):
        RGLMeasured(tmp_path / "missing.bsdf")


def test_truncated_file_raises_format_error(tmp_path):
    cut = tmp_path / "cut.bsdf"
    cut.write_bytes(FELT.read_bytes()[:5000])
    with pytest.raises(FormatError, match="cut.bsdf"):
        read_tensor_file(cut)


# --- Mitsuba's convention, checked on a Lambertian BSDF ---------------------------------
@needs_mitsuba
def test_mitsuba_eval_includes_the_cosine_of_wo(rng):
    """The code path RGLMeasured uses returns ρ/π·cos θ_wo for a ``diffuse`` BSDF."""
    from kesbrdf.references.rgl import eval_plugin, load_plugin

    rho = [0.2, 0.5, 0.8]
    diffuse = load_plugin({"type": "diffuse", "reflectance": {"type": "rgb", "value": rho}})
    w_param, w_out = _upper(rng, 500), _upper(rng, 500)
    got = eval_plugin(diffuse, w_param, w_out)
    expected = np.asarray(rho) / np.pi * w_out[:, 2:3]
    np.testing.assert_allclose(got, expected, rtol=1e-5)  # float32 evaluation


# --- the evaluator's conventions --------------------------------------------------------
@needs_mitsuba
def test_values_positive_finite_and_shaped(felt, rng):
    wi, wr = _upper(rng, 3000, POSITIVE_THETA_MAX_DEG), _upper(rng, 3000, POSITIVE_THETA_MAX_DEG)
    f = felt(wi.reshape(30, 100, 3), wr.reshape(30, 100, 3))
    assert f.shape == (30, 100, 3)
    assert np.all(np.isfinite(f)) and np.all(f > 0)
    # broadcasting one light against many viewers
    assert felt(wi[:1], wr).shape == (3000, 3)


@needs_mitsuba
def test_unmeasured_grazing_region_is_zero_not_negative(felt, rng):
    wi, wr = _upper(rng, 20000, 89.0), _upper(rng, 20000, 89.0)
    f = felt(wi, wr)
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    zero = np.any(f == 0, axis=-1)
    assert np.mean(zero) < 0.01  # measured 0.13 %
    grazing = np.minimum(wi[zero, 2], wr[zero, 2])
    assert np.all(grazing < np.cos(np.radians(POSITIVE_THETA_MAX_DEG)))


@needs_mitsuba
def test_below_horizon_is_zero_and_nan_propagates(felt):
    up = np.array([0.0, 0.6, 0.8])
    down = np.array([0.0, 0.6, -0.8])
    nan = np.array([np.nan, 0.0, 1.0])
    f = felt(np.stack([up, down, nan]), np.stack([down, up, up]))
    assert np.all(f[:2] == 0.0)
    assert np.all(np.isnan(f[2]))


@needs_mitsuba
def test_normal_incidence_value(felt):
    """Regression: f_r at θ_i = θ_r = 0, measured (0.2410, 0.2493, 0.2962)/sr."""
    z = np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(felt(z, z)[0], [0.2410, 0.2493, 0.2962], rtol=1e-3)


@needs_mitsuba
def test_isotropy(felt, rng):
    wi, wr = _upper(rng, 4000), _upper(rng, 4000)
    f = felt(wi, wr)
    for angle in rng.uniform(0, 2 * np.pi, 3):
        g = felt(_rotate_z(wi, angle), _rotate_z(wr, angle))
        assert np.max(np.abs(g - f) / f) < ISOTROPY_RTOL


@needs_mitsuba
def test_reciprocity_within_the_measurement(felt, rng):
    wi, wr = _upper(rng, 4000), _upper(rng, 4000)
    a, b = felt(wi, wr), felt(wr, wi)
    rel = np.abs(a - b) / np.maximum(a, b)
    assert np.median(rel) < RECIPROCITY_MEDIAN_MAX
    assert np.percentile(rel, 95) < RECIPROCITY_P95_MAX


#: Relative agreement of two single-precision evaluations of the same data.
FLOAT32_RTOL = 2e-5


@needs_mitsuba
def test_viewer_parameterisation_is_the_transpose(felt, rng):
    viewer = RGLMeasured(FELT, parameterised_by="viewer")
    wi, wr = _upper(rng, 500), _upper(rng, 500)
    # the plugin interpolates in single precision (llvm_ad_rgb): the two calls may
    # round differently, by a few float32 ulps over a handful of operations
    np.testing.assert_allclose(viewer(wi, wr), felt(wr, wi), rtol=FLOAT32_RTOL)


def test_unknown_parameterisation_raises():
    with pytest.raises(FormatError, match="parameterised_by"):
        RGLMeasured(FELT, parameterised_by="camera")


@needs_mitsuba
def test_albedo_at_most_one(felt):
    from kesbrdf.validate.diagnostics import directional_albedo

    wi = spherical_to_cartesian(np.radians([0.0, 30.0, 60.0, 80.0]), np.radians([0.0, 45.0, 90.0, 200.0]))
    albedo = directional_albedo(felt, wi)
    assert albedo.shape == (4, 3)
    assert np.all(albedo <= 1.0)
    assert np.all(albedo >= ALBEDO_MIN)


# --- end to end: four orientations of an isotropic felt -> KES -> every orientation ----
@pytest.fixture(scope="module")
def paper_fit(felt):
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    m = measure(felt)
    return m, fit(m)


@needs_mitsuba
def test_in_plane_data_is_the_same_at_every_orientation(felt):
    """What makes the end-to-end check possible: the felt is isotropic on the paper line
    (up to the pole's rounding at γ = 0)."""
    from kesbrdf.measure.gonio import measure

    ref = measure(felt, orientations_deg=(0.0,))
    for psi in (45.0, 112.5):
        other = measure(felt, orientations_deg=(psi,))
        assert np.max(np.abs(other.values - ref.values) / ref.values) < POLE_ANISOTROPY_RTOL


@needs_mitsuba
def test_fit_returns_every_measured_sample(paper_fit):
    from kesbrdf.models.brdf import evaluate

    m, model = paper_fit
    np.testing.assert_allclose(evaluate(model, m.wi, m.wr), m.values, rtol=1e-9)


@needs_mitsuba
def test_reciprocal_felt_is_reproduced_at_every_orientation(felt):
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    sym = _Symmetrised(felt)
    model = fit(measure(sym))
    held = measure(sym, orientations_deg=HELD_OUT_DEG)
    for mapping in ("deviation", "halfvector"):
        pred = evaluate(model, held.wi, held.wr, mapping)
        assert np.max(np.abs(pred - held.values) / held.values) < HELD_OUT_SYMMETRIC_RTOL


@needs_mitsuba
def test_raw_felt_held_out_error_is_bounded_by_its_non_reciprocity(felt, paper_fit):
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.measure.gonio import measure

    m, model = paper_fit
    transposed = felt(m.wr, m.wi)
    non_reciprocity = np.max(np.abs(m.values - transposed) / np.maximum(m.values, transposed))
    held = measure(felt, orientations_deg=HELD_OUT_DEG)
    for mapping in ("deviation", "halfvector"):
        err = np.max(np.abs(evaluate(model, held.wi, held.wr, mapping) - held.values) / held.values)
        assert err < non_reciprocity
        assert err < HELD_OUT_RAW_MEASURED * REGRESSION_MARGIN


def _hemisphere_metrics(felt, model, mapping):
    """Worst (rmse, log_rmse) over the two Fig. 6 lights."""
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.validate.compare import HEMISPHERE_LIGHTS_DEG, hemisphere_directions, metrics

    wr, _, _ = hemisphere_directions()
    wr = wr.reshape(-1, 3)
    worst = (0.0, 0.0)
    for theta_i, phi_i in HEMISPHERE_LIGHTS_DEG:
        wi = spherical_to_cartesian(np.radians(theta_i), np.radians(phi_i))[None, :]
        res = metrics(evaluate(model, wi, wr, mapping), felt(wi, wr))["all"]
        worst = (max(worst[0], res["rmse"]), max(worst[1], res["log_rmse"]))
    return worst


@needs_mitsuba
@pytest.mark.parametrize("mapping", ["deviation", "halfvector", "paper"])
def test_hemisphere_errors_of_the_paper_protocol_model(felt, paper_fit, mapping):
    _, model = paper_fit
    rmse, log_rmse = _hemisphere_metrics(felt, model, mapping)
    ref_rmse, ref_log = HEMISPHERE_MEASURED[("kes", mapping)]
    assert rmse < ref_rmse * REGRESSION_MARGIN
    assert log_rmse < ref_log * REGRESSION_MARGIN


@needs_mitsuba
def test_hemisphere_errors_of_the_halfdiff_model(felt):
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.halfdiff import fit_halfdiff

    model = fit_halfdiff(measure(felt, protocol="dense", step_deg=6))
    rmse, log_rmse = _hemisphere_metrics(felt, model, "halfdiff")  # the kind's one mapping
    ref_rmse, ref_log = HEMISPHERE_MEASURED[("kes-halfdiff", "halfdiff")]
    assert rmse < ref_rmse * REGRESSION_MARGIN
    assert log_rmse < ref_log * REGRESSION_MARGIN
