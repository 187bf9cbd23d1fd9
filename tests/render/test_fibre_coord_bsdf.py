"""The ``kesbrdf_fibre_coord`` plugin: agreement with FibreCoordModel.evaluate, reciprocity,
the horizon, dispatch from the model file, and a tiny sphere render."""

from types import SimpleNamespace

import numpy as np
import pytest

from bsdf_helpers import eval_fr as _eval, random_pairs

pytestmark = pytest.mark.render

#: Relative agreement with the float64 numpy model.  The plugin runs in float32: the
#: fibre coordinates go through atan2 (u*, φ, θ_d), the base prior through the Seeliger
#: sums and Fresnel, and the corrections multiply by e^(p+n+d) with node slopes up to
#: 3/(5°) on the hand-set file.  Measured worst over 20 000 random pairs: 3.5e-5 (fitted)
#: and 5.7e-5 (hand-set, the steepest corrections); 1e-4 leaves a margin of 1.7-3x.
EVAL_RTOL = 1e-4
#: Absolute floor (1/sr), for values near 0; both files have f_r ≥ 8.5e-3 1/sr above the
#: horizon (k_d), so the relative term decides there.
EVAL_ATOL = 1e-6
#: Reciprocity: every factor of (C1) is symmetric in ωi ↔ ωr (kesbrdf.models.fibre_coord);
#: float32 evaluates the two orders with different rounding: measured 2.8e-6 relative
#: over 20 000 pairs (as tests/render/test_prior_bsdf.py).
RECIP_RTOL = 1e-4


@pytest.fixture(scope="module")
def coord_files(tmp_path_factory, fibre_coord_fit):
    """The shared fit (KES residual, θ_d law fixed), and the same base prior with hand-set
    corrections: random node values in ±1.5 (past any fitted slope), a free θ_d law and
    an energy scale over (cos θ, φ) with different values per channel, no residual."""
    from kesbrdf.models.fibre_coord import CoordPrior, FibreCoordModel, _n_params

    _, fitted = fibre_coord_fit
    rng = np.random.default_rng(5)
    theta = rng.uniform(-1.5, 1.5, _n_params(3, True))
    energy = SimpleNamespace(scale=rng.uniform(0.3, 1.0, (17, 12, 3)), bound=0.95)
    handset = FibreCoordModel(CoordPrior(fitted.prior.base, theta, True), None, channels=fitted.channels,
                              energy=energy)
    folder = tmp_path_factory.mktemp("coord")
    out = {}
    for name, model in (("fitted", fitted), ("handset", handset)):
        model.save(folder / f"{name}.kes.json")
        out[name] = (folder / f"{name}.kes.json", model)
    return out


def _load(path, **kw):
    import mitsuba as mi

    return mi.load_dict({"type": "kesbrdf_fibre_coord", "filename": str(path), **kw})


@pytest.mark.parametrize("name", ["fitted", "handset"])
def test_eval_agrees_with_numpy(render_module, coord_files, rng, name):
    path, model = coord_files[name]
    wi, wr = random_pairs(rng, 400)
    got = _eval(_load(path), wi, wr)
    want = model.evaluate(wi, wr)
    assert np.all(np.isfinite(got)) and np.all(want > 0)
    err = np.abs(got - want)
    assert not (err > EVAL_RTOL * want + EVAL_ATOL).any(), (name, float(np.max(err / want)))
    # the corrections matter: the same base prior alone differs by far more than the tolerance
    if name == "handset":
        base = model.prior.base(wi, wr)
        assert np.median(np.abs(base - want) / want) > 0.1


@pytest.mark.parametrize("name", ["fitted", "handset"])
def test_reciprocal(render_module, coord_files, rng, name):
    wi, wr = random_pairs(rng, 400)
    bsdf = _load(coord_files[name][0])
    a, b = _eval(bsdf, wi, wr), _eval(bsdf, wr, wi)
    np.testing.assert_allclose(a, b, rtol=RECIP_RTOL, atol=EVAL_ATOL)


def test_below_horizon_is_zero(render_module, coord_files, rng):
    path, _ = coord_files["handset"]
    wi, wr = random_pairs(rng, 300)
    flip = np.array([1.0, 1.0, -1.0])
    bsdf = _load(path)
    assert np.all(_eval(bsdf, wi * flip, wr) == 0) and np.all(_eval(bsdf, wi, wr * flip) == 0)
    assert np.all(_eval(bsdf, wi * flip, wr * flip) == 0)


def test_render_uses_this_plugin(render_module, coord_files, tmp_path):
    """``kesbrdf render`` path: the file names its plugin, and a 32x24 sphere at 4 spp draws."""
    import mitsuba as mi

    from kesbrdf.render.scenes import RenderOptions, bsdf_dict, load_scene

    path, model = coord_files["fitted"]
    assert model.render_plugin() == ("kesbrdf_fibre_coord", {})
    assert bsdf_dict(path, RenderOptions())["type"] == "kesbrdf_fibre_coord"
    scene = load_scene(path, "sphere", RenderOptions(resolution=(32, 24), spp=4))
    cloth = [s for s in scene.shapes() if s.id() == "cloth"][0]
    assert str(cloth.bsdf()).startswith("FibreCoordBSDF[")
    img = np.array(mi.render(scene, spp=4))
    assert img.shape[:2] == (24, 32) and np.all(np.isfinite(img))
    # the sphere is lit: its pixels carry light (a broken eval would leave it black)
    assert np.mean(img[..., :3]) > 1e-3


#: chi² budget: half of tests/render/test_prior_bsdf.py's samples (one incidence, a fast test).
CHI2_SAMPLES = 100_000


def test_chi2_sampling(render_module, coord_files, tmp_path, monkeypatch):
    """The inherited half-vector sampler draws this model's lobe: its pdf is its own."""
    import math

    import mitsuba as mi
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    monkeypatch.chdir(tmp_path)  # a failing chi² test writes chi2_data.py
    d = {"type": "kesbrdf_fibre_coord", "filename": str(coord_files["handset"][0])}
    theta = 0.6
    wi = mi.ScalarVector3f(math.sin(theta) * math.cos(0.7), math.sin(theta) * math.sin(0.7), math.cos(theta))
    sample, pdf = BSDFAdapter("kesbrdf_fibre_coord", d, wi=wi)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
                         sample_count=CHI2_SAMPLES, res=64, ires=16, seed=2)
    assert test.run(), test.messages
