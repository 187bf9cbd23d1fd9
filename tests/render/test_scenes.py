"""Scenes: every scene renders; UVs carry the warp; drape folders are read."""

import json

import numpy as np
import pytest

pytestmark = pytest.mark.render

#: Tiny renders keep the shared CPU free (issue 4).
RES = (64, 64)
SPP = 8
#: Two renders that differ only in float32 rounding of φ (exact 90° table roll).
SAME_IMAGE_ATOL = 2e-3
#: Rotating the warp by 90° must change the swatch's highlight by more than this
#: (mean absolute difference relative to the mean image level).
MIN_ROTATION_EFFECT = 0.05


def _opts(**kw):
    from kesbrdf.render.scenes import RenderOptions

    return RenderOptions(spp=SPP, resolution=RES, **kw)


@pytest.mark.parametrize("scene", ["sphere", "swatch", "drape", "dressform"])
def test_scene_renders(render_module, model_files, scene):
    from kesbrdf.render.scenes import load_scene, render_scene

    path, _ = model_files["rgb"]
    opts = _opts(env="sky", light="area")
    img = render_scene(load_scene(path, scene, opts), opts)
    assert img.shape == (RES[1], RES[0], 3)
    assert np.all(np.isfinite(img)) and img.mean() > 0.01


def _direct_swatch(path, uv_rotation_deg):
    """Swatch lit by the area light only, emitter sampling only: deterministic eval."""
    from kesbrdf.render.scenes import load_scene, render_scene

    opts = _opts(env="none", light="area", uv_rotation_deg=uv_rotation_deg,
                 integrator={"type": "direct", "emitter_samples": 1, "bsdf_samples": 0})
    return render_scene(load_scene(path, "swatch", opts), opts)


def test_rotating_uvs_swaps_warp_and_weft(render_module, model_files, rolled_model_file, tmp_path):
    """UVs turned by 90° render exactly like the model table turned by 90° in φ."""
    path, model = model_files["aniso"]
    rolled = rolled_model_file(model, tmp_path / "rolled.kes.json")
    rotated_uv = _direct_swatch(path, 90)
    rotated_table = _direct_swatch(rolled, 0)
    original = _direct_swatch(path, 0)
    np.testing.assert_allclose(rotated_uv, rotated_table, atol=SAME_IMAGE_ATOL)
    effect = np.abs(rotated_uv - original).mean() / original.mean()
    assert effect > MIN_ROTATION_EFFECT, effect


def test_highlight_elongates_along_the_wide_lobe_axis(render_module, model_files):
    """Ward alpha_y > alpha_x: the highlight on the flat swatch stretches along the weft.

    With the warp along image x (u along world x), the highlight's spread along the
    image's x direction is smaller than after turning the UVs by 90°.
    """
    path, _ = model_files["aniso"]

    def spread_x(img):
        lum = img.mean(axis=-1)
        w = np.clip(lum - np.quantile(lum, 0.5), 0, None)
        x = np.arange(lum.shape[1])
        px = w.sum(axis=0) / w.sum()
        mx = (px * x).sum()
        return float(np.sqrt((px * (x - mx) ** 2).sum()))

    assert spread_x(_direct_swatch(path, 0)) < spread_x(_direct_swatch(path, 90))


def test_read_drape_errors_name_the_file(tmp_path):
    from kesbrdf.errors import FormatError
    from kesbrdf.render.scenes import read_drape

    with pytest.raises(FormatError, match="drape.json"):
        read_drape(tmp_path)
    (tmp_path / "drape.json").write_text(json.dumps({"fps": 24, "frames": ["frame_0000.ply"]}))
    with pytest.raises(FormatError, match="frame_0000.ply"):
        read_drape(tmp_path)


def test_unknown_scene_lists_names(render_module, model_files):
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.render.scenes import load_scene

    with pytest.raises(KesbrdfError, match="sphere, swatch, drape, dressform"):
        load_scene(model_files["rgb"][0], "cube", _opts())


def test_save_image_png_records_provenance(render_module, model_files, tmp_path):
    from PIL import Image

    from kesbrdf.render.scenes import provenance, save_image

    img = np.full((4, 5, 3), 0.5, np.float32)
    out = save_image(tmp_path / "x.png", img, provenance(model_files["rgb"][0], "sphere", _opts()))
    meta = json.loads(Image.open(out).text["kesbrdf"])
    assert meta["scene"] == "sphere" and len(meta["model_sha256"]) == 64
    assert list(tmp_path.iterdir()) == [out]  # no temporary left behind


def test_shading_frame_is_warp_weft_normal(render_module, tmp_path):
    """On a PLY mesh Mitsuba's local frame is (∂p/∂u, n × ∂p/∂u, n) = (warp, weft, normal)."""
    import mitsuba as mi

    from kesbrdf.io.ply import write_ply
    from kesbrdf.render import mesh

    p, n, uv, f = mesh.swatch(n=5)
    write_ply(tmp_path / "s.ply", p, f, n, uv)
    scene = mi.load_dict({"type": "scene", "s": {"type": "ply", "filename": str(tmp_path / "s.ply")}})
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(0.1, 1.0, 0.1), mi.Vector3f(0, -1, 0)))
    frame = si.sh_frame
    np.testing.assert_allclose(np.array(frame.s).ravel(), [1, 0, 0], atol=1e-6)  # u: warp
    np.testing.assert_allclose(np.array(frame.t).ravel(), [0, 0, -1], atol=1e-6)  # v: weft
    np.testing.assert_allclose(np.array(frame.n).ravel(), [0, 1, 0], atol=1e-6)
    assert float(np.array(si.wi).ravel()[2]) > 0  # camera above: front side


@pytest.mark.parametrize("up", ["y", "z"])
def test_drape_up_axis_is_guessed_from_the_fall(render_module, tmp_path, up):
    from kesbrdf.render.mesh import procedural_drape
    from kesbrdf.render.scenes import read_drape

    folder = procedural_drape(tmp_path / "d", frames=3, n=9)  # written z-up
    meta = json.loads((folder / "drape.json").read_text())
    del meta["up_axis"]
    if up == "y":  # rewrite the frames y-up
        import mitsuba as mi

        from kesbrdf.io.ply import write_ply

        for name in meta["frames"]:
            params = mi.traverse(mi.load_dict({"type": "ply", "filename": str(folder / name)}))
            p = np.array(params["vertex_positions"]).reshape(-1, 3)
            f = np.array(params["faces"]).reshape(-1, 3)
            uv = np.array(params["vertex_texcoords"]).reshape(-1, 2)
            write_ply(folder / name, np.stack([p[:, 0], p[:, 2], -p[:, 1]], -1), f, None, uv)
    (folder / "drape.json").write_text(json.dumps(meta))
    assert read_drape(folder).up_axis == up
