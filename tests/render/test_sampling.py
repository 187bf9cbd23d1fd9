"""Importance sampling of the ``kesbrdf`` BSDF: Mitsuba's chi² test and efficiency."""

import math

import numpy as np
import pytest

pytestmark = pytest.mark.render

#: Chi² test size: 2e5 samples on a 64 x 128 spherical histogram, the pdf integrated
#: with 16 x 16 points per cell (4 x 4 under-resolves the lobe near grazing views).
CHI2_SAMPLES = 200_000
CHI2_RES = 64
CHI2_IRES = 16


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """A failing chi² test writes chi2_data.py into the working directory: keep it out of the repo."""
    monkeypatch.chdir(tmp_path)


def _chi2(path, theta, phi=0.7, **kw):
    import mitsuba as mi
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    wi = mi.ScalarVector3f(math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta))
    sample, pdf = BSDFAdapter("kesbrdf", {"type": "kesbrdf", "filename": str(path), **kw}, wi=wi)
    test = ChiSquareTest(
        domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
        sample_count=CHI2_SAMPLES, res=CHI2_RES, ires=CHI2_IRES, seed=2,
    )
    return test.run(), test


@pytest.mark.parametrize("theta", [0.2, 0.9, 1.3])
@pytest.mark.parametrize("mapping", ["deviation", "halfvector"])
def test_chi2_lobe_sampling(render_module, model_files, mapping, theta):
    path, _ = model_files["rgb"]
    ok, test = _chi2(path, theta, mapping=mapping)
    assert ok, test.messages


def test_chi2_two_sided_back_face(render_module, model_files):
    path, _ = model_files["aniso"]
    ok, test = _chi2(path, math.pi - 0.6, two_sided=True)
    assert ok, test.messages


def test_chi2_cosine_sampling(render_module, model_files):
    path, _ = model_files["rgb"]
    ok, test = _chi2(path, 0.6, sampling="cosine")
    assert ok, test.messages


def test_lobe_sampling_reduces_variance(render_module, model_files):
    """For a glossy model, lobe sampling gives much lower weight variance than cosine."""
    import drjit as dr
    import mitsuba as mi

    path, _ = model_files["aniso"]
    n = 100_000
    variances = {}
    for mode in ("lobe", "cosine"):
        bsdf = mi.load_dict({"type": "kesbrdf", "filename": str(path), "sampling": mode})
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(11, n)
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(math.sin(0.5), 0.0, math.cos(0.5))
        _, w = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
        variances[mode] = float(np.var(np.array(w)[0]))
    # a narrow lobe (alpha_x = 0.06) under cosine sampling has a heavy-tailed weight;
    # importance sampling must cut the variance at least by 4 (RMSE by 2, the issue's goal)
    assert variances["lobe"] * 4 < variances["cosine"], variances


def test_alias_table_cache_returns_the_same_table_and_owns_its_copy(render_module):
    """alias_table keeps recent tables by content (every scene of a model rebuilds its
    sampler): a repeat gives the same table, and a caller's edit does not reach the cache."""
    from kesbrdf.render.sampling import alias_table

    w = np.random.default_rng(3).random(500)
    p1, a1 = alias_table(w)
    p1[:] = -1.0
    a1[:] = 0
    p2, a2 = alias_table(w.copy())
    assert np.all(p2 >= 0) and np.all(p2 <= 1)
    # the table still reproduces the weights: P(k) = (p_k + Σ_{i: alias_i = k} (1 - p_i)) / n
    got = (p2 + np.bincount(a2, weights=1.0 - p2, minlength=w.size)) / w.size
    np.testing.assert_allclose(got, w / w.sum(), rtol=1e-5, atol=1e-7)
