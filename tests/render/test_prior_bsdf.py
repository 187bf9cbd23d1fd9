"""The ``kesbrdf_prior`` plugin: agreement with FibrePriorModel.evaluate, reciprocity,
colour, dispatch on the model kind, and chi² sampling."""

import math

import numpy as np
import pytest

from bsdf_helpers import eval_fr as _eval, random_pairs

_pairs = random_pairs


pytestmark = pytest.mark.render

#: Relative agreement with the float64 numpy model.  The plugin runs in float32; over
#: 4000 random pairs the worst relative error measured is 2.5e-5 (paper and dense fits,
#: filament and staple families: float32 angles through atan2/acos, the Seeliger sums
#: and the residual's texture coordinates), so 2e-4 leaves an 8x margin.
EVAL_RTOL = 2e-4
#: Absolute floor relative to the largest value of the set: where f is 10⁻⁷ of its peak
#: (a staple fit's k_d is 3e-8 1/sr) float32 rounding of the angles dominates; the
#: worst absolute error measured is 2.3e-6 of the peak.
EVAL_ATOL_OF_PEAK = 1e-5
#: Reciprocity of the plugin: every factor is symmetric in ωi ↔ ωr (docs/prior.md), but
#: float32 evaluates the two orders with different rounding; measured 3.5e-6 relative.
RECIP_RTOL = 1e-4
#: chi² budget, as tests/render/test_sampling.py.
CHI2_SAMPLES = 200_000
CHI2_RES = 64
CHI2_IRES = 16


@pytest.fixture(scope="module")
def prior_files(tmp_path_factory):
    """Fibre-prior fits of the Sadeghi satin, saved: paper protocol with the BIC's choice
    (filament/filament, KES residual), paper with a staple warp, a coarse dense grid (15°)
    with a staple weft (half/difference residual, free θ_d law), and the pure prior of
    the first."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.fibre_prior import FibrePriorModel
    from kesbrdf.render.reference_bsdf import make_reference

    ref = make_reference("sadeghi-satin")
    paper = measure(ref, protocol="paper")
    dense = measure(ref, protocol="dense", step_deg=15.0)  # 144 pairs: a 1.7 s fit instead of 6 s
    models = {
        "paper-filament": FibrePriorModel.fit_measurement(paper, kinds=("filament", "filament")),
        "paper-staple": FibrePriorModel.fit_measurement(paper, kinds=("staple", "filament")),
        "dense-staple": FibrePriorModel.fit_measurement(dense, kinds=("filament", "staple")),
    }
    first = models["paper-filament"]
    models["pure-prior"] = FibrePriorModel(first.prior, None, channels=first.channels)
    # the dense fit's free θ_d law held outside a narrow range of ωi·ωr (PriorSpec.theta_d_range)
    from dataclasses import replace

    from kesbrdf.models.fibre_physics import FibrePrior

    staple = models["dense-staple"].prior
    held = FibrePrior(replace(staple.spec, theta_d_range=(-0.3, 0.2)), staple.theta, staple.report, staple.cov)
    assert held.spec.free_theta_d
    models["held-theta-d"] = FibrePriorModel(held, None, channels=first.channels)
    # the satin fits need no energy scale (albedo < 0.95): hand-set tables of g in
    # [0.2, 1] with different values per channel exercise the plugin's lookup, over
    # cos θ as fits write it and over (cos θ, φ) as energy_scale also reads
    from types import SimpleNamespace

    for name, shape in (("energy-scaled", (17, 1, 3)), ("energy-scaled-phi", (17, 12, 3))):
        scale = np.random.default_rng(3).uniform(0.2, 1.0, shape)
        models[name] = FibrePriorModel(first.prior, first.residual, channels=first.channels,
                                       energy=SimpleNamespace(scale=scale, bound=0.95))
    folder = tmp_path_factory.mktemp("prior")
    out = {}
    for name, model in models.items():
        path = folder / f"{name}.kes.json"
        model.save(path)
        out[name] = (path, model)
    return out


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """A failing chi² test writes chi2_data.py into the working directory."""
    monkeypatch.chdir(tmp_path)




def _load(path, **kw):
    import mitsuba as mi

    return mi.load_dict({"type": "kesbrdf_prior", "filename": str(path), **kw})




@pytest.mark.parametrize("name", ["paper-filament", "paper-staple", "dense-staple", "pure-prior", "energy-scaled",
                                  "energy-scaled-phi", "held-theta-d"])
def test_eval_agrees_with_numpy(render_module, prior_files, rng, name):
    path, model = prior_files[name]
    assert model.prior.spec.kinds == {"paper-staple": ("staple", "filament"), "dense-staple": ("filament", "staple"),
                                      "held-theta-d": ("filament", "staple")}.get(name, ("filament", "filament"))
    wi, wr = _pairs(rng)
    got = _eval(_load(path), wi, wr)
    want = model.evaluate(wi, wr)
    assert np.all(np.isfinite(got))
    tol = EVAL_RTOL * np.abs(want) + EVAL_ATOL_OF_PEAK * np.abs(want).max()
    err = np.abs(got - want)
    assert not (err > tol).any(), (name, float(np.max(err / np.maximum(np.abs(want), 1e-30))))


@pytest.mark.parametrize("name", ["paper-filament", "dense-staple", "energy-scaled", "energy-scaled-phi"])
def test_reciprocal(render_module, prior_files, rng, name):
    wi, wr = _pairs(rng, 2000)
    bsdf = _load(prior_files[name][0])
    a, b = _eval(bsdf, wi, wr), _eval(bsdf, wr, wi)
    np.testing.assert_allclose(a, b, rtol=RECIP_RTOL, atol=EVAL_ATOL_OF_PEAK * a.max())


def test_base_color_replaces_kd_and_tint_scales_the_lobe(render_module, prior_files, rng):
    path, model = prior_files["paper-filament"]
    wi, wr = _pairs(rng, 1000)
    f = model.evaluate(wi, wr)
    kd = np.exp([model.prior.parameters()[f"log_kd_{c}"] for c in range(3)])
    base, tint = np.array([0.6, 0.3, 0.1]), np.array([1.0, 0.5, 2.0])
    got = _eval(_load(path, base_color="0.6,0.3,0.1", lobe_tint="1,0.5,2"), wi, wr)
    want = np.maximum(base / np.pi + tint * (f - kd), 0.0)
    np.testing.assert_allclose(got, want, rtol=EVAL_RTOL, atol=EVAL_ATOL_OF_PEAK * want.max())


def test_below_horizon_is_zero_unless_two_sided(render_module, prior_files, rng):
    path, _ = prior_files["paper-filament"]
    wi, wr = _pairs(rng, 300)
    flip = np.array([1.0, 1.0, -1.0])
    front = _eval(_load(path), wi, wr)
    assert np.all(_eval(_load(path), wi * flip, wr * flip) == 0)
    # the back is the front mirrored through the fabric plane (same warp and weft)
    np.testing.assert_allclose(-_eval(_load(path, two_sided=True), wi * flip, wr * flip), front, rtol=1e-6)


def test_scenes_draw_a_fibre_prior_file_with_this_plugin(render_module, prior_files):
    from kesbrdf.render.bsdf import check_model
    from kesbrdf.render.scenes import RenderOptions, bsdf_dict, load_scene

    path, _ = prior_files["dense-staple"]
    assert check_model(path).kind == "fibre-prior"
    d = bsdf_dict(path, RenderOptions(base_color=(0.5, 0.2, 0.1)))
    assert d["type"] == "kesbrdf_prior" and "mapping" not in d and d["base_color"] == "0.5,0.2,0.1"
    # a scene built from the file alone (as `kesbrdf render` and the colourway sheet do)
    scene = load_scene(path, "sphere", RenderOptions(resolution=(16, 12), spp=1))
    cloth = [s for s in scene.shapes() if s.id() == "cloth"][0]
    assert str(cloth.bsdf()).startswith("FibrePriorBSDF[")
    # a KES-only option is refused, not dropped silently
    from kesbrdf.errors import KesbrdfError

    with pytest.raises(KesbrdfError, match="applies to kes models only"):
        bsdf_dict(path, RenderOptions(mapping="halfvector"))


#: Parameters a new fabric of the same structure changes, per model of ``prior_files``:
#: every number of a filament prior; for a staple prior all but the tilt profile (u_lo,
#: u_hi, log_s, c2), whose zero-weight node blocks are part of the kernel's structure.
_NEW_FABRIC = {
    "paper-filament": ("log_kd", "log_ks", "u_lo", "u_hi", "log_s", "c2", "rho"),
    "paper-staple": ("log_kd", "log_ks", "rho", "psi"),
}


@pytest.mark.parametrize("name", sorted(_NEW_FABRIC))
def test_a_new_fabric_of_the_same_structure_reuses_the_compiled_kernel(render_module, prior_files, tmp_path, name):
    """The prior's numbers are opaque kernel parameters (kesbrdf.render.jit): a second fabric
    with the same filament/staple structure launches the kernels compiled for the first.
    With the numbers as literals every fabric of a batch compiled its scene again (2-5 s
    of CPU a studio scene)."""
    import drjit as dr
    import mitsuba as mi

    from kesbrdf.models.fibre_physics import FibrePrior
    from kesbrdf.models.fibre_prior import FibrePriorModel

    path, model = prior_files[name]
    prior = model.prior
    x = np.array(prior.theta, float)
    for k, n in enumerate(prior.spec.names()):
        if any(n.startswith(p) or n.split("_", 1)[-1].startswith(p) for p in _NEW_FABRIC[name]):
            x[k] += 0.05 if not n.endswith("psi") else 0.02 * np.sign(x[k])
    other = tmp_path / "other.kes.json"
    FibrePriorModel(FibrePrior(prior.spec, x, prior.report, prior.cov), None, channels=model.channels).save(other)
    first_path = tmp_path / "first.kes.json"
    FibrePriorModel(prior, None, channels=model.channels).save(first_path)

    def render(p):
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 2}, "light": {"type": "constant"},
            "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8},
                       "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0])},
            "cloth": {"type": "sphere", "bsdf": {"type": "kesbrdf_prior", "filename": str(p)}}})
        return np.asarray(mi.render(scene, spp=2))

    was = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = render(first_path)
        dr.kernel_history()  # clears it
        second = render(other)
        launched = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, was)
    # hits in memory, not on disk: with literals the second fabric's kernel is new to this
    # process (it may still be on the disk cache from an earlier run of the test)
    assert launched and all(k["cache_hit"] and not k.get("cache_disk", False) for k in launched), \
        [(k["hash"], k["cache_hit"], k.get("cache_disk")) for k in launched]
    # the reused kernel read the new fabric's numbers: the image changed
    assert np.abs(second - first).max() > 1e-3 * np.abs(first).max()


def test_wrong_kind_is_rejected_in_one_line(render_module, tmp_path):
    from kesbrdf.errors import ModelError
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard
    from kesbrdf.render.prior_bsdf import check_prior_model

    path = tmp_path / "w.kes.json"
    fit(measure(AnisotropicWard(0.1, 0.2))).save(path)
    with pytest.raises(ModelError, match="reads models of kind 'fibre-prior', got 'kes'"):
        check_prior_model(path)


@pytest.mark.parametrize("name,theta", [("paper-filament", 0.3), ("paper-filament", 1.1), ("dense-staple", 0.6)])
def test_chi2_prior_sampling(render_module, prior_files, name, theta):
    import mitsuba as mi
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    d = {"type": "kesbrdf_prior", "filename": str(prior_files[name][0])}
    wi = mi.ScalarVector3f(math.sin(theta) * math.cos(0.7), math.sin(theta) * math.sin(0.7), math.cos(theta))
    sample, pdf = BSDFAdapter("kesbrdf_prior", d, wi=wi)
    test = ChiSquareTest(
        domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
        sample_count=CHI2_SAMPLES, res=CHI2_RES, ires=CHI2_IRES, seed=2,
    )
    assert test.run(), test.messages


def test_compare_render_cli_scores_kes_and_prior(render_module, tmp_path):
    """``kesbrdf compare-render --kind kes --with-prior``: both models of one measurement, one panel."""
    import json

    from PIL import Image

    from kesbrdf.cli.main import main

    out = tmp_path / "cmp.png"
    assert main(["compare-render", "--reference", "satin-ward", "--kind", "kes", "--with-prior", "--spp", "4",
                 "--resolution", "48x36", "-o", str(out)]) == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    assert {k: v["kind"] for k, v in meta["models"].items()} == {"kes": "kes", "fibre-prior": "fibre-prior"}
    assert meta["flip"] == meta["models"]["kes"]["flip"]
    assert all(0.0 <= v["flip"] <= 1.0 and np.isfinite(v["rel_rmse"]) for v in meta["models"].values())
    # reference | KES | FLIP | prior+residual | FLIP
    assert Image.open(out).size[0] == 5 * 48
