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
    (["--exposure", "bright"], "'card'"),
    (["--exposure", "nan"], "stops"),
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


def test_exposure_card_meters_once_and_every_image_keeps_it(render_module, model_files, tmp_path, monkeypatch):
    """``--exposure card``: render and colourways meter the scene on the grey card once
    (kesbrdf.render.exposure.meter_exposure) and write with that exposure; a number of
    stops is used as given, with no metering."""
    import numpy as np
    from PIL import Image

    from kesbrdf.render import exposure

    metered = []
    monkeypatch.setattr(exposure, "meter_exposure", lambda model, scene, opts, **kw: metered.append(scene) or -3.0)
    stills = {}
    for name, flag in (("card", "card"), ("zero", "0"), ("minus3", "-3")):
        out = tmp_path / f"{name}.png"
        assert _cli("render", model_files["rgb"][0], "--scene", "sphere", "-o", out, "--spp", 2,
                    "--resolution", "32x24", "--exposure", flag) == 0
        stills[name] = np.asarray(Image.open(out), float)
    assert metered == ["sphere"]  # only the card render metered
    np.testing.assert_array_equal(stills["card"], stills["minus3"])  # -3 stops, as metered
    assert stills["card"].mean() < 0.5 * stills["zero"].mean()  # 1/8 the light, sRGB-encoded: ≈ 0.4
    assert _cli("colourways", model_files["rgb"][0], "-o", tmp_path / "sheet.png", "--scene", "swatch",
                "--spp", 1, "--resolution", "16x16", "--exposure", "card") == 0
    assert metered == ["sphere", "swatch"]  # one metering for the whole sheet
