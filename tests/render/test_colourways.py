"""Colourways: same lobe, new body colour, at least six tiles."""

import numpy as np
import pytest

pytestmark = pytest.mark.render


def test_sheet_has_one_tile_per_colour_in_that_colour(render_module, model_files, tmp_path):
    from kesbrdf.render.colourways import DEFAULT_COLOURWAYS, render_colourways, tile_means
    from kesbrdf.render.scenes import RenderOptions

    cw = DEFAULT_COLOURWAYS[:6]
    out = render_colourways(model_files["aniso"][0], tmp_path / "sheet.png",
                            RenderOptions(spp=4, resolution=(48, 48), env="uniform", light="none"),
                            scene="swatch", colourways=cw, columns=3)
    means = tile_means(out, len(cw), columns=3)
    # the dominant channel of each tile is that of its colour (crimson red, emerald green, navy blue...)
    for (name, rgb), m in zip(cw, means):
        if max(rgb) - min(rgb) > 0.2:
            assert np.argmax(m) == np.argmax(rgb), (name, m)


def test_gloss_is_kept_across_colourways(render_module, model_files):
    """The lobe part of f_r does not depend on base_color (docs/method.md, "Colour")."""
    import drjit as dr
    import mitsuba as mi

    path, _ = model_files["aniso"]
    wi = mi.Vector3f(-0.3, 0.1, 0.95)
    wr = mi.Vector3f(0.35, -0.05, 0.93)
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = dr.normalize(wr)
    lobes = []
    for base in ("0.8,0.1,0.1", "0.1,0.1,0.6"):
        bsdf = mi.load_dict({"type": "kesbrdf", "filename": str(path), "base_color": base})
        f = np.array(bsdf.eval(mi.BSDFContext(), si, dr.normalize(wi))).ravel()
        base_rgb = np.array([float(c) for c in base.split(",")])
        lobes.append(f - base_rgb / np.pi * float(dr.normalize(wi).z[0]))
    np.testing.assert_allclose(lobes[0], lobes[1], rtol=1e-5)


def test_fewer_than_six_colours_is_an_error(render_module, model_files, tmp_path):
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.render.colourways import parse_colourways, render_colourways
    from kesbrdf.render.scenes import RenderOptions

    cw = parse_colourways("red=0.5,0,0;blue=0,0,0.5")
    assert cw == [("red", (0.5, 0.0, 0.0)), ("blue", (0.0, 0.0, 0.5))]
    with pytest.raises(KesbrdfError, match="at least 6"):
        render_colourways(model_files["rgb"][0], tmp_path / "s.png", RenderOptions(), colourways=cw)
