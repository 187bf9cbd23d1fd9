"""Drape sequence → video: every frame kept atomically, interrupted runs resume."""

import json

import numpy as np
import pytest

pytestmark = pytest.mark.render

FRAMES = 3


@pytest.fixture
def drape_dir(tmp_path):
    from kesbrdf.render.mesh import procedural_drape

    return procedural_drape(tmp_path / "drape", frames=FRAMES, n=9)


def _opts(**kw):
    from kesbrdf.render.scenes import RenderOptions

    return RenderOptions(spp=2, resolution=(32, 24), **kw)


class Interrupt(Exception):
    pass


def test_interrupted_run_resumes(render_module, model_files, drape_dir, tmp_path):
    from kesbrdf.render.animation import render_animation

    out = tmp_path / "anim.gif"
    path, _ = model_files["rgb"]

    def stop_after_two(done, total, skipped):
        if done == 2:
            raise Interrupt

    with pytest.raises(Interrupt):
        render_animation(path, drape_dir, out, _opts(), progress=stop_after_two)
    frames = tmp_path / "anim_frames"
    assert sorted(p.name for p in frames.glob("frame_*.png")) == ["frame_0000.png", "frame_0001.png"]
    assert not out.exists()
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".part")]

    seen = []
    render_animation(path, drape_dir, out, _opts(), progress=lambda d, t, s: seen.append(s))
    assert seen == [True, True, False]
    from PIL import Image

    assert Image.open(out).n_frames == FRAMES
    meta = json.loads((tmp_path / "anim.gif.json").read_text())
    assert meta["drape_frames"] == [f"frame_{k:04d}.ply" for k in range(FRAMES)]


def test_changed_parameters_render_again(render_module, model_files, drape_dir, tmp_path):
    from kesbrdf.render.animation import render_animation

    out = tmp_path / "anim.gif"
    path, _ = model_files["rgb"]
    render_animation(path, drape_dir, out, _opts())
    seen = []
    render_animation(path, drape_dir, out, _opts(base_color=(0.1, 0.5, 0.1)), progress=lambda d, t, s: seen.append(s))
    assert seen == [False] * FRAMES


def test_mp4_output(render_module, model_files, drape_dir, tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from kesbrdf.render.animation import render_animation

    out = render_animation(model_files["rgb"][0], drape_dir, tmp_path / "anim.mp4", _opts())
    assert out.read_bytes()[4:8] == b"ftyp"  # an MP4 container


def test_video_suffix_is_checked(render_module, model_files, drape_dir, tmp_path):
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.render.animation import render_animation

    with pytest.raises(KesbrdfError, match=r"\.mp4 or \.gif"):
        render_animation(model_files["rgb"][0], drape_dir, tmp_path / "anim.avi", _opts())


def test_frames_follow_the_drape(render_module, model_files, drape_dir, tmp_path):
    """The sheet falls during the sequence: first and last frames differ."""
    from PIL import Image

    from kesbrdf.render.animation import render_animation

    render_animation(model_files["rgb"][0], drape_dir, tmp_path / "a.gif", _opts())
    first = np.asarray(Image.open(tmp_path / "a_frames" / "frame_0000.png"), float)
    last = np.asarray(Image.open(tmp_path / "a_frames" / f"frame_{FRAMES - 1:04d}.png"), float)
    assert np.abs(first - last).mean() > 2.0  # 8-bit levels
