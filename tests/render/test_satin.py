"""Satin that reads as satin: colourways on BSDF values, and UV rotation on the image."""

import numpy as np
import pytest

from kesbrdf.geometry import spherical_to_cartesian

pytestmark = pytest.mark.render

#: The plugin's float32 evaluation against the float64 numpy lobe: the plugin's own
#: agreement bound (tests/render/test_bsdf.py EVAL_RTOL), plus float32 rounding of
#: f = body + lobe before the body is subtracted again (body up to 0.25 1/sr: 3e-8 x 8).
VALUE_RTOL = 1e-4
VALUE_ATOL = 1e-6


@pytest.fixture(scope="module")
def black_satin_model(tmp_path_factory):
    """The KES model of the virtual black satin (paper protocol, as the demo fits it)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.sadeghi2013 import black_satin

    path = tmp_path_factory.mktemp("satin") / "black_satin.kes.json"
    model = fit(measure(black_satin()), fallback="log")
    model.save(path)
    return path, model


def _pairs(rng, n=2000):
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0.1, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0.1, 1, n)), rng.uniform(0, 2 * np.pi, n))
    return wi.astype(np.float32).astype(float), wr.astype(np.float32).astype(float)


def test_colourways_change_the_body_only(render_module, black_satin_model, rng):
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.render.colourways import DEFAULT_COLOURWAYS, colourway_values

    path, model = black_satin_model
    wi, wr = _pairs(rng)
    values = colourway_values(path, DEFAULT_COLOURWAYS, wi, wr)
    lobe = evaluate(model, wi, wr) - model.body  # the measured lobe, q / sqrt(cos cos)
    for name, v in values.items():
        # the lobe part is the measured lobe in every colourway
        np.testing.assert_allclose(v["lobe"], lobe, rtol=VALUE_RTOL, atol=VALUE_ATOL, err_msg=name)
    # two colourways differ by exactly (A - B)/pi everywhere
    a, b = values["crimson"]["f"], values["navy"]["f"]
    want = (np.array(dict(DEFAULT_COLOURWAYS)["crimson"]) - np.array(dict(DEFAULT_COLOURWAYS)["navy"])) / np.pi
    np.testing.assert_allclose(a - b, np.broadcast_to(want, a.shape), rtol=0, atol=1e-6)


def test_black_colourway_is_the_measured_black_body(render_module, black_satin_model, rng):
    """Without a base colour the body is the measured one (2 % albedo), not mid-grey."""
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.render.colourways import DEFAULT_COLOURWAYS, colourway_values

    path, model = black_satin_model
    assert dict(DEFAULT_COLOURWAYS)["black"] is None
    wi, wr = _pairs(rng, 500)
    v = colourway_values(path, [("black", None)], wi, wr)["black"]
    np.testing.assert_allclose(v["f"], evaluate(model, wi, wr), rtol=VALUE_RTOL, atol=VALUE_ATOL)
    # black-dyed textile: body albedo pi*c of 1-3 % (kesbrdf.references.sadeghi2013.black_satin_fabric)
    assert np.all(np.pi * v["body"] < 0.03) and np.all(np.pi * v["body"] > 0.005)


def test_dyed_satin_keeps_a_white_sheen(render_module, black_satin_model):
    """At the warp-float highlight the lobe is neutral, so the colour there whitens.

    Saturation (max - min)/max of body b plus a white sheen s is (b_max - b_min)/(b_max + s):
    below 0.6x the body's own saturation means s > 0.67 b_max.  Measured: crimson
    0.96 -> 0.49, navy 0.91 -> 0.29 (sheen 0.152 1/sr at the 30 deg warp mirror).
    """
    from kesbrdf.render.colourways import colourway_values

    path, _ = black_satin_model
    t = np.radians(30.0)
    wi = np.array([[-np.sin(t), 0.0, np.cos(t)]])  # light 30 deg, warp plane
    wr = np.array([[np.sin(t), 0.0, np.cos(t)]])  # viewer at the mirror direction
    v = colourway_values(path, [("crimson", (0.50, 0.02, 0.05)), ("navy", (0.02, 0.04, 0.22))], wi, wr)

    def saturation(c):
        return (c.max() - c.min()) / c.max()

    for name, d in v.items():
        sheen = d["lobe"][0]
        assert sheen.max() / sheen.min() < 1.01, (name, sheen)  # white: R = G = B within 1 %
        assert saturation(d["f"][0]) < 0.6 * saturation(d["body"]), (name, d["f"][0], d["body"])


#: Image difference required between UV rotations, in units of the Monte-Carlo noise
#: floor (the same difference between two seeds of one image).  With independent noise,
#: diff^2 = signal^2 + noise^2, so diff > 2.5 noise means the rotation changes the image
#: by more than 2.3 noise.  Measured at 64x48: 3.8x (model, drape, 64 spp), 11x
#: (reference, swatch, 16 spp).  The model's ratio is the smaller one because its
#: highlight is less anisotropic than the reference's (docs/rendering.md).
UV_DIFF_OVER_NOISE = 2.5
#: The highlight ellipse of the reference on the swatch turns (measured 89 deg -> 0 deg).
UV_MIN_ROTATION_DEG = 45.0


def _render(bsdf, scene, rot, seed, spp=16):
    from kesbrdf.render import scenes as S
    from kesbrdf.render.compare import cloth_mask

    o = S.RenderOptions(spp=spp, resolution=(64, 48), env="none", light="area", uv_rotation_deg=rot, seed=seed)
    sc = S.load_scene(None, scene, o, cloth_bsdf=bsdf)
    return S.render_scene(sc, o), cloth_mask(sc)


def test_uv_rotation_moves_the_model_highlight_on_folds(render_module, black_satin_model):
    from kesbrdf.render.compare import relative_rmse
    from kesbrdf.render.scenes import RenderOptions, bsdf_dict

    bsdf = bsdf_dict(black_satin_model[0], RenderOptions())
    a, mask = _render(bsdf, "drape", 0, 0, spp=64)
    a2, _ = _render(bsdf, "drape", 0, 1, spp=64)
    b, _ = _render(bsdf, "drape", 90, 1, spp=64)
    noise = relative_rmse(a2, a, mask)
    diff = relative_rmse(b, a, mask)
    assert diff > UV_DIFF_OVER_NOISE * noise, (diff, noise)


def test_uv_rotation_turns_the_reference_highlight(render_module):
    from kesbrdf.render.compare import relative_rmse
    from kesbrdf.render.highlight import highlight_stats, orientation_difference_deg
    from kesbrdf.render.reference_bsdf import reference_bsdf_dict

    bsdf = reference_bsdf_dict("sadeghi-black-satin")
    a, mask = _render(bsdf, "swatch", 0, 0)
    a2, _ = _render(bsdf, "swatch", 0, 1)
    b, _ = _render(bsdf, "swatch", 90, 1)
    assert relative_rmse(b, a, mask) > UV_DIFF_OVER_NOISE * relative_rmse(a2, a, mask)
    sa, sb = highlight_stats(a, mask), highlight_stats(b, mask)
    assert orientation_difference_deg(sa["orientation_deg"], sb["orientation_deg"]) > UV_MIN_ROTATION_DEG, (sa, sb)


def test_fade_extrapolation_changes_only_the_unmeasured_deviations(render_module, black_satin_model, rng):
    """``extrapolation="fade"`` = ``hold`` up to γ_max, the body alone beyond γ_max + 6°."""
    import math

    import drjit as dr
    import mitsuba as mi

    from kesbrdf.models.brdf import to_phi_gamma
    from kesbrdf.render.bsdf import FADE_DEG

    path, model = black_satin_model
    wi, wr = _pairs(rng, 4000)
    out = {}
    for ex in ("hold", "fade"):
        bsdf = mi.load_dict({"type": "kesbrdf", "filename": str(path), "extrapolation": ex})
        si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
        si.wi = mi.Vector3f(*wr.T)
        out[ex] = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*wi.T))).T / wi[:, 2:3]
    _, gamma = to_phi_gamma(wi, wr, model.default_mapping)  # the plugin reads the table with the model's own
    g_max = model.gamma_grid[-1]
    inside = gamma < g_max - 1e-4
    beyond = gamma > g_max + math.radians(FADE_DEG) + 1e-4
    assert inside.sum() > 100 and beyond.sum() > 100  # both regions are exercised
    np.testing.assert_array_equal(out["fade"][inside], out["hold"][inside])
    np.testing.assert_allclose(out["fade"][beyond], np.broadcast_to(model.body, out["fade"][beyond].shape), rtol=1e-5)


def test_black_satin_side_by_side_fade_is_closer(render_module):
    """The satin preset side by side with its model: fading the unmeasured lobe helps.

    Measured at 160x120/64 spp: FLIP 0.43 (hold) vs 0.29 (fade), noise floor 0.045;
    at this test's 64x48/16 spp: 0.40 vs 0.24, noise floor 0.064.
    """
    from kesbrdf.render.compare import compare_render, default_options

    r = {ex: compare_render("sadeghi-black-satin", "paper", "sphere",
                            default_options(spp=16, resolution=(64, 48), extrapolation=ex), noise_floor=False,
                            models=("kes",))
         for ex in ("hold", "fade")}
    assert r["fade"]["flip"] < r["hold"]["flip"] - 0.05, {k: v["flip"] for k, v in r.items()}
    assert r["fade"]["rel_rmse"] < 0.8 * r["hold"]["rel_rmse"], {k: v["rel_rmse"] for k, v in r.items()}


def test_parse_measured_colourway():
    from kesbrdf.render.colourways import parse_colourways

    assert parse_colourways("black=measured;red=0.5,0,0") == [("black", None), ("red", (0.5, 0.0, 0.0))]
