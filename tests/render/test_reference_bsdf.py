"""Reference BRDFs as Mitsuba BSDFs: agreement with their numpy evaluation and chi² sampling."""

import math

import numpy as np
import pytest

from bsdf_helpers import eval_fr as _eval, random_pairs

_pairs = random_pairs


pytestmark = pytest.mark.render

#: Relative agreement with the float64 numpy reference.  The plugin runs in float32;
#: measured worst case over 4000 random pairs is 7e-5 (velvet, whose kernel sums ~40
#: tangent terms of mixed sign exponents), 2.6e-5 for Ashikhmin-Shirley (a power
#: with exponents up to 400), 6e-7 for Ward.
EVAL_RTOL = 2e-4
#: Absolute floor relative to the largest value of the set: where the value itself is
#: tiny (far tails) float32 rounding of the angles dominates.
EVAL_ATOL_OF_PEAK = 1e-5
#: chi² budget, as tests/render/test_sampling.py.
CHI2_SAMPLES = 200_000
CHI2_RES = 64
CHI2_IRES = 16

EVAL_CASES = [
    ("ward", None),
    ("satin-ward", None),
    ("ashikhmin-shirley", None),
    ("ggx", None),
    ("ggx", {"alpha_x": 0.05, "alpha_y": 0.6, "eta": 2.2, "rho_d": [0.9, 0.1, 0.0], "k_s": 0.5}),
    ("sadeghi-satin", None),
    ("sadeghi-black-satin", None),
    ("sadeghi-velvet", None),
    # the published, non-reciprocal forward model (light -> eye) of Sadeghi et al.
    ("sadeghi-satin", {"reciprocal": False}),
    ("rgl-felt-white", None),
]


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """A failing chi² test writes chi2_data.py into the working directory."""
    monkeypatch.chdir(tmp_path)






@pytest.mark.parametrize("name,params", EVAL_CASES, ids=lambda v: str(v) if v else "default")
def test_reference_bsdf_agrees_with_numpy(render_module, rng, name, params):
    import mitsuba as mi

    from kesbrdf.render.reference_bsdf import make_reference, reference_bsdf_dict

    ref = make_reference(name, params)
    wi, wr = _pairs(rng)
    got = _eval(mi.load_dict(reference_bsdf_dict(name, two_sided=False, params=params)), wi, wr)
    want = ref(wi, wr)
    assert np.all(np.isfinite(got))
    tol = EVAL_RTOL * np.abs(want) + EVAL_ATOL_OF_PEAK * np.abs(want).max()
    bad = np.abs(got - want) > tol
    assert not bad.any(), (name, float(np.max(np.abs(got - want) / np.maximum(np.abs(want), 1e-30))))


def test_warp_is_the_uv_u_tangent(render_module):
    """The satin's warp-float highlight is stretched across the warp (local x).

    Sadeghi satin at normal light: the highlight extends along y (a viewer tilted toward
    the weft still sees the warp floats' reflection) and falls off fast along x.
    """
    import mitsuba as mi

    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    bsdf = mi.load_dict(reference_bsdf_dict("sadeghi-black-satin", two_sided=False))
    t = math.radians(25)
    light = np.array([[0.0, 0.0, 1.0]] * 2)
    view = np.array([[math.sin(t), 0.0, math.cos(t)], [0.0, math.sin(t), math.cos(t)]])
    f = _eval(bsdf, light, view)[:, 1]
    # numpy reference: 0.111 (toward the weft) vs 0.038 1/sr (toward the warp), 2.96x;
    # a swapped frame would give the inverse ratio
    assert f[1] > 2 * f[0], f


def test_two_sided_mirrors_the_back(render_module, rng):
    import mitsuba as mi

    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    wi, wr = _pairs(rng, 300)
    flip = np.array([1.0, 1.0, -1.0])
    front = _eval(mi.load_dict(reference_bsdf_dict("ward", two_sided=False)), wi, wr)
    one = mi.load_dict(reference_bsdf_dict("ward", two_sided=False))
    two = mi.load_dict(reference_bsdf_dict("ward", two_sided=True))
    assert np.all(_eval(one, wi * flip, wr * flip) == 0)
    np.testing.assert_allclose(-_eval(two, wi * flip, wr * flip), front, rtol=1e-6)


def test_unknown_reference_is_rejected(render_module):
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    with pytest.raises(KesbrdfError, match="expected one of"):
        reference_bsdf_dict("gold-leaf")


CHI2_CASES = [
    ("ward", 0.3), ("ward", 1.1),
    ("ashikhmin-shirley", 0.3), ("ashikhmin-shirley", 1.1),
    ("sadeghi-satin", 0.3), ("sadeghi-satin", 1.1),
    ("sadeghi-black-satin", 1.1),
    # velvet at 63° is not tested: 0.8 % of the proposal's samples land where the
    # microcylinder masking makes f_r exactly 0; Mitsuba's adapter drops zero-weight
    # samples but the pdf counts them, so the test rejects a correct sampler there.
    ("sadeghi-velvet", 0.3),
    ("rgl-felt-white", 0.6),
]


@pytest.mark.parametrize("name,theta", CHI2_CASES)
def test_chi2_reference_sampling(render_module, name, theta):
    import mitsuba as mi
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    wi = mi.ScalarVector3f(math.sin(theta) * math.cos(0.7), math.sin(theta) * math.sin(0.7), math.cos(theta))
    d = reference_bsdf_dict(name, two_sided=False)
    sample, pdf = BSDFAdapter(d["type"], d, wi=wi)
    test = ChiSquareTest(
        domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
        sample_count=CHI2_SAMPLES, res=CHI2_RES, ires=CHI2_IRES, seed=2,
    )
    assert test.run(), test.messages
