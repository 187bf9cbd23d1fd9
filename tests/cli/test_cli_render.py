"""The ``kesbrdf render`` and ``kesbrdf colourways`` commands, called through the real CLI."""

import pytest

pytestmark = pytest.mark.render


def _cli(*argv):
    from kesbrdf.cli.main import main

    return main([str(a) for a in argv])


def test_render_sphere_png(render_module, model_files, tmp_path):
    out = tmp_path / "s.png"
    assert _cli("render", model_files["rgb"][0], "--scene", "sphere", "-o", out, "--spp", 2,
                "--resolution", "32x24", "--base-color", "0.6,0.1,0.1", "--env", "sky", "--light", "sun",
                "--one-sided", "--mapping", "halfvector") == 0
    from PIL import Image

    assert Image.open(out).size == (32, 24)


def test_render_animation_gif(render_module, model_files, tmp_path):
    from kesbrdf.render.mesh import procedural_drape

    drape = procedural_drape(tmp_path / "d", frames=2, n=9)
    out = tmp_path / "a.gif"
    assert _cli("render", model_files["rgb"][0], "--scene", "drape", "--animation", drape, "-o", out,
                "--spp", 1, "--resolution", "24x16") == 0
    assert out.is_file()


@pytest.mark.parametrize("argv, message", [
    (["--resolution", "32"], "WxH"),
    (["--base-color", "red"], "R,G,B"),
    (["--base-color", "2,0,0"], "[0, 1]"),
    (["--mapping", "deviation", "-o", "x.mp4"], "--animation"),
])
def test_render_user_errors(render_module, model_files, tmp_path, capsys, argv, message):
    args = ["render", model_files["rgb"][0], "-o", tmp_path / "x.png", "--spp", 1, "--resolution", "8x8"]
    args += argv
    assert _cli(*args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_colourways_command(render_module, model_files, tmp_path):
    out = tmp_path / "sheet.png"
    assert _cli("colourways", model_files["rgb"][0], "-o", out, "--scene", "swatch", "--spp", 1,
                "--resolution", "24x24", "--columns", 3) == 0
    from PIL import Image

    assert Image.open(out).size == (72, 72)  # 8 default colourways in 3 columns: 3 rows
