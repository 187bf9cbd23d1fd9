"""The body term's one rule (kesbrdf.models.body, docs/models.md "The body term").

f_r = c + lobe with lobe ≥ 0, so a body above the darkest reading is a floor the data
contradict (eq. B1); a fitted body may exceed it by the reading's noise only (eq. B2).
The fibre prior fitted freely to a dense (900-sample) measurement of the Sadeghi black
satin puts k_d at 0.039 1/sr: 7× the reference's own body and 6.7× the darkest reading;
fibre-coord's corrections on that base cannot bring the dark samples below the floor
(log round trip 0.35), so fibre-coord now also fits a body-bounded candidate and keeps
it when it reproduces the readings clearly better.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from kesbrdf.errors import KESError
from kesbrdf.geometry import grazing_albedo
from kesbrdf.measure.gonio import measure
from kesbrdf.models.body import BODY_NOISE_Z, body_bound, body_value, log_body_upper
from kesbrdf.models.fibre_coord import BODY_KEEP_RATIO, fit_coord
from kesbrdf.models.fibre_physics import fit_prior
from kesbrdf.references.sadeghi2013 import black_satin

#: The fitted body may be at most this factor from the reference's body (its volume
#: term's directional albedo at normal view over π, 0.0054 1/sr).  A factor 2 is an
#: albedo error of at most π·0.0054 ≈ 0.017, a ninth of the satin's 0.151; the fit
#: before the rule was 7.2× (0.11 of albedo in a floor, the grey "black" satin).
BODY_FACTOR = 2.0
#: fibre-coord's log round trip to the dense satin's 900 readings (RMS of ln f − ln y).
#: With the body bounded: 0.12; before: 0.35 (the floor held every dark reading up).
#: 0.2 leaves room for BLAS rounding and the seed while failing the old fit.
COORD_RMS_LOG_MAX = 0.2


def test_bound_is_the_darkest_reading_and_its_noise():
    y = np.array([[0.5, 0.2], [0.03, 0.4], [0.1, -0.01]])
    assert body_bound(y).tolist() == [0.03, 0.0]  # a reading at or below 0: no body
    sigma = np.full_like(y, 0.01)
    assert body_bound(y, sigma) == pytest.approx([0.03 + BODY_NOISE_Z * 0.01, 0.01])
    assert body_bound(np.array([[np.nan], [0.2], [0.1]])).tolist() == [0.1]
    # ln of the bound, floored just above the parametric fit's smallest ln k_d where it is 0
    upper = log_body_upper(y)
    assert upper[0] == pytest.approx(math.log(0.03)) and upper[1] < -39


def test_kes_option_follows_the_rule():
    y = np.array([[0.5, 0.2], [0.03, 0.4]])
    assert body_value("auto", y, 2)[0].tolist() == [0.03, 0.2]
    assert body_value("none", y, 2)[0].tolist() == [0.0, 0.0]
    c, mode = body_value(0.1, y, 2)
    assert c.tolist() == [0.1, 0.1] and mode == "value"
    with pytest.raises(KESError, match="expected body 'auto', 'lambertian', 'none' or a number per channel, got 'dark'"):
        body_value("dark", y, 2)


@pytest.fixture(scope="module")
def satin_dense():
    ref = black_satin()
    m = measure(ref, protocol="dense", noise=0.02, rng=1)
    a = grazing_albedo(ref, [0.0], 0.0, 24, 48)[0, 0]
    a_surface = grazing_albedo(black_satin(dye_factor=0.0), [0.0], 0.0, 24, 48)[0, 0]
    return ref, m, (a - a_surface) / math.pi


@pytest.fixture(scope="module")
def satin_prior(satin_dense):
    """The free fit (the ``fibre-prior`` kind's): k_d 0.039 1/sr, above every reading's floor."""
    _, m, _ = satin_dense
    return fit_prior(m, kinds=("filament", "filament"))


def _kd(params, C=3):
    return np.exp([params[f"log_kd_{c}"] for c in range(C)])


def test_reference_body_is_the_volume_term(satin_dense):
    # the black satin's dyed volume term: 1.7 % albedo (sadeghi2013.black_satin_fabric)
    assert satin_dense[2] == pytest.approx(0.0054, rel=0.05)


def test_free_prior_body_is_the_floor_the_data_contradict(satin_dense, satin_prior):
    # what issue 17 saw: the log fit puts the in-plane floor into k_d
    _, m, ref_body = satin_dense
    kd = _kd(satin_prior.parameters())
    assert np.all(kd > 5 * body_bound(m.values, m.uncertainty)) and np.all(kd > 5 * ref_body)


def test_bounded_prior_body_on_dense_black_satin_is_what_the_data_support(satin_dense):
    _, m, ref_body = satin_dense
    bounded = fit_prior(m, kinds=("filament", "filament"), bound_body=True)
    assert bounded.report["body_bounded"]
    kd = _kd(bounded.parameters())
    assert np.all(kd <= body_bound(m.values, m.uncertainty) * (1 + 1e-9))
    assert np.all(kd <= BODY_FACTOR * ref_body) and np.all(kd >= ref_body / BODY_FACTOR), (kd, ref_body)


@pytest.mark.slow  # a 900-row fibre-coord fit (~14 s): make test-long, which CI runs
def test_coord_body_and_round_trip_on_dense_black_satin(satin_dense, satin_prior):
    ref, m, ref_body = satin_dense
    coord = fit_coord(m, base=satin_prior)
    # the bounded candidate halves the log misfit of the free one, so it is kept
    assert coord.report["body"]["kept"] == "bounded", coord.report["body"]
    assert coord.report["body"]["bounded_rms_log"] <= BODY_KEEP_RATIO * coord.report["body"]["free_rms_log"]
    kd = _kd(coord.parameters())
    assert np.all(kd <= body_bound(m.values, m.uncertainty) * (1 + 1e-9))
    assert np.all(kd <= BODY_FACTOR * ref_body) and np.all(kd >= ref_body / BODY_FACTOR), (kd, ref_body)
    assert coord.report["rms_log"] < COORD_RMS_LOG_MAX
    # still reciprocal, and no more energy out than in at normal view
    rng = np.random.default_rng(3)
    w = rng.normal(size=(2, 200, 3))
    w[..., 2] = np.abs(w[..., 2])
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    assert np.allclose(coord(w[0], w[1]), coord(w[1], w[0]), rtol=1e-9, atol=0)
    assert np.all(grazing_albedo(coord, [0.0, 60.0], 0.0, 24, 48) < 1.0)


# -- the Fresnel-like body of kes tables (eq. B3-B6) --------------------------------------

from kesbrdf.models import kes  # noqa: E402
from kesbrdf.models.body import FAR_RATIO_MAX, BodyLaw, fit_body_law, fresnel_like  # noqa: E402
from kesbrdf.references.registry import make_reference  # noqa: E402
from kesbrdf.validate.lofo import score, scoring_truths  # noqa: E402

#: The fitted shape against the reference's own at θ = 30°, 60°, 80° (g(μ) over g(1)):
#: measured |Δg| ≤ 0.10 on the GGX (Fresnel η = 1.5) and ≤ 0.04 on the Ashikhmin–Shirley
#: references at 2 % noise; 0.15 fails a Lambertian body (Δg up to 0.62 at 80°).
SHAPE_TOL = 0.15
#: Hemisphere NRMSE (the two Fig. 6 hemispheres) of the paper protocol's kes table with
#: the law over the Lambertian reading: measured 0.102 / 0.362 (GGX) and 0.077 / 0.480
#: (Ashikhmin–Shirley), ratios 0.28 and 0.16; at most half is asserted.
LAW_GAIN_MAX = 0.5


def _ggx():
    from kesbrdf.references.ggx import AnisotropicGGX

    return AnisotropicGGX(0.15, 0.3, eta=1.5, rho_d=[0.5, 0.3, 0.2], k_s=0.6)


def _as():
    from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

    return AshikhminShirley(40, 200, R_s=0.06, R_d=[0.5, 0.3, 0.2])


def test_body_law_is_reciprocal_bounded_and_lambertian_at_a_zero():
    law = BodyLaw(0.9, 4.0)
    mu = np.linspace(0.0, 1.0, 11)
    assert np.array_equal(law(mu[:, None], mu[None, :]), law(mu[None, :], mu[:, None]))
    g = law.shape(mu)
    assert g[-1] == 1.0 and np.all((g >= 0) & (g <= 1)) and np.all(np.diff(g) >= 0)
    assert BodyLaw(0.0, 7.0).lambertian and np.all(BodyLaw(0.0, 7.0).shape(mu) == 1.0)
    assert fresnel_like(law) and not fresnel_like(BodyLaw(0.5, 1.0)) and not fresnel_like(BodyLaw(0.3, 4.0)) and not fresnel_like(BodyLaw(0.55, 4.0))
    with pytest.raises(KESError):
        BodyLaw(1.2, 2.0)


@pytest.mark.parametrize("name", ["ggx", "as"])
def test_fresnel_weighted_body_is_found_with_its_shape_and_under_every_reading(name):
    from kesbrdf.optics import fresnel_dielectric

    ref = _ggx() if name == "ggx" else _as()
    m = measure(ref, noise=0.02, rng=1)
    c, law, report = fit_body_law(m.values, m.wi, m.wr)
    assert law is not None, report
    B = c[None, :] * law(m.wi[:, 2], m.wr[:, 2])[:, None]
    assert np.all(B <= m.values * (1 + 1e-12))  # eq. (B4)
    mu = np.cos(np.radians([30.0, 60.0, 80.0]))
    if name == "ggx":
        truth = (1 - fresnel_dielectric(mu, 1.5)) / (1 - fresnel_dielectric(np.array(1.0), 1.5))
    else:
        truth = (1 - (1 - mu / 2) ** 5) / (1 - 0.5 ** 5)
    assert np.max(np.abs(law.shape(mu) - truth)) < SHAPE_TOL, (law, law.shape(mu), truth)


@pytest.mark.parametrize("name", ["ward", "rgl-felt-white", "irawan-cotton-twill", "sadeghi-black-satin", "sadeghi-satin"])
def test_lambertian_woven_and_satin_bodies_keep_the_lambertian_rule(name):
    """Ward's body is Lambertian (eq. B5 fails: g(87°) 0.91); the felt and the twill fall off
    early (B5); the satins' far readings are their lobes' tails, 3.9-4.3x a law (B6)."""
    m = measure(make_reference(name), noise=0.02, rng=1)
    c, law, report = fit_body_law(m.values, m.wi, m.wr)
    assert law is None and not report["kept"], report
    np.testing.assert_array_equal(c, body_bound(m.values))
    if name.startswith("sadeghi"):
        assert report["far_ratio"] > 2 * FAR_RATIO_MAX


@pytest.fixture(scope="module")
def ggx_case():
    ref = _ggx()
    m = measure(ref, noise=0.02, rng=1)
    return ref, m, kes.fit(m), kes.fit(m, body="lambertian")


def test_kes_table_with_a_law_returns_every_sample_and_is_reciprocal(ggx_case, tmp_path):
    from kesbrdf.io.model_file import load_model

    ref, m, model, _ = ggx_case
    assert model.body_law is not None and model.diagnostics["body_law"]["kept"]
    np.testing.assert_allclose(model.evaluate(m.wi, m.wr), m.values, rtol=1e-9)
    rng = np.random.default_rng(4)
    v = rng.normal(size=(2, 500, 3))
    v[..., 2] = np.abs(v[..., 2]) + 0.05
    wi, wr = v / np.linalg.norm(v, axis=-1, keepdims=True)
    np.testing.assert_allclose(model.evaluate(wi, wr), model.evaluate(wr, wi), rtol=1e-12)
    again = load_model(model.save(tmp_path / "law.kes.json"))
    assert again.body_law == model.body_law
    np.testing.assert_array_equal(again.evaluate(wi, wr), model.evaluate(wi, wr))
    # a file without the law (written before it) reads the body as Lambertian
    fields, arrays = model.to_payload()
    assert "body_law" in fields
    plain = kes.Model(**{**{k: getattr(model, k) for k in ("channels", "parameters", "diagnostics", "input_info")},
                         **arrays, "sigma": model.sigma})
    assert plain.body_law is None
    np.testing.assert_allclose(plain.evaluate(m.wi[:1], m.wr[:1] * np.array([1, 1, 1])) - plain.body,
                               model.evaluate(m.wi[:1], m.wr[:1]) - model.body * model.body_law(m.wi[:1, 2], m.wr[:1, 2])[:, None],
                               rtol=1e-12)


@pytest.mark.parametrize("name", ["ggx", "as"])
def test_a_fresnel_like_body_predicts_the_hemispheres_of_fresnel_weighted_references(name, ggx_case):
    if name == "ggx":
        ref, m, model, lambertian = ggx_case
    else:
        ref = _as()
        m = measure(ref, noise=0.02, rng=1)
        model, lambertian = kes.fit(m), kes.fit(m, body="lambertian")
    t = scoring_truths(ref)
    with_law, without = score(model.evaluate, None, t), score(lambertian.evaluate, None, t)
    assert with_law["hemispheres"] < LAW_GAIN_MAX * without["hemispheres"], (with_law, without)
    # the plane of incidence is the same table: the held-out orientations do not move
    assert with_law["orientations"] == pytest.approx(without["orientations"], rel=0.05)
