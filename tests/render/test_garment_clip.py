"""The garment clip: the scene moved frame to frame equals the scene reloaded; MP4 + GIF."""

import numpy as np
import pytest

#: Vertex positions/normals of a moved scene against a reloaded one: float32 rounding of
#: the same rotation (measured 2e-7).
MOVE_TOL = 1e-6


@pytest.fixture(scope="module")
def garment_drape(tmp_path_factory):
    pytest.importorskip("newton")
    from kesbrdf.cloth.drape import simulate_drape

    out = tmp_path_factory.mktemp("garment-drape")
    simulate_drape("garment", out, 4, resolution=8, turn_deg=40.0, turn_start_s=0.0, turn_duration_s=0.1)
    return out


@pytest.mark.render
@pytest.mark.cloth
def test_moved_scene_equals_reloaded_scene(garment_drape, model_files, render_module):
    import mitsuba as mi

    from kesbrdf.render import animation, scenes

    path, _ = model_files["rgb"]
    opts = scenes.RenderOptions(spp=1, resolution=(32, 18), light="studio", env="studio-hdr")
    drape = scenes.read_drape(garment_drape)
    assert drape.scene == "garment" and drape.moving == (0,) and drape.body_rotation_deg[-1] == pytest.approx(40.0)
    moved = scenes.load_scene(path, "garment", opts, drape=drape, frame=0)
    update = animation._FrameUpdater(moved, drape)
    update(3)
    fresh = mi.traverse(scenes.load_scene(path, "garment", opts, drape=drape, frame=3))
    for key in ("cloth.vertex_positions", "cloth.vertex_normals", "collider_0.vertex_positions",
                "collider_0.vertex_normals"):
        assert np.abs(np.array(fresh[key]) - np.array(update.params[key])).max() < MOVE_TOL, key
    # the body really turned between frame 0 and 3
    first = mi.traverse(scenes.load_scene(path, "garment", opts, drape=drape, frame=0))
    assert np.abs(np.array(first["collider_0.vertex_positions"]) - np.array(fresh["collider_0.vertex_positions"])).max() > 0.05


@pytest.mark.render
@pytest.mark.cloth
def test_clip_writes_upscaled_mp4_and_gif(garment_drape, model_files, render_module, tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from PIL import Image

    from kesbrdf.render import animation, scenes

    path, _ = model_files["rgb"]
    opts = scenes.RenderOptions(spp=2, resolution=(32, 18), light="studio", env="studio-hdr", tonemap="aces",
                                denoise=True)
    out = animation.render_animation(path, garment_drape, tmp_path / "clip.mp4", opts, first_frame=2,
                                     gif=tmp_path / "clip.gif", gif_width=32, upscale_to=(64, 36))
    frames = sorted((tmp_path / "clip_frames").glob("frame_*.png"))
    assert out.is_file() and (tmp_path / "clip.gif").is_file() and len(frames) == 2  # frames 2 and 3
    assert Image.open(frames[0]).size == (64, 36)
    gif = Image.open(tmp_path / "clip.gif")
    assert gif.size == (32, 18) and gif.n_frames == 2
