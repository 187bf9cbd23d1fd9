"""``kesbrdf export -o NAME.ext`` without ``--format``: the format from the ending, its
errors, and the agreement line of the analytic-fit formats (MaterialX, USD).

Before, ``export -o x.gltf`` without ``--format`` was refused, and mtlx/usd printed
``agreement …: fit; fit_error; exact=False`` without a number; these tests fail there.
"""

import pytest

from kesbrdf.cli.export import agreement_line
from kesbrdf.cli.main import main
from kesbrdf.errors import ExportError
from kesbrdf.export import FORMATS, export, format_module
from kesbrdf.export.endings import endings, format_for_output, resolve_format


@pytest.mark.parametrize("name, fmt", [("a.gltf", "gltf"), ("a.GLB", "glb"), ("a.mtlx", "mtlx"), ("a.usda", "usd"),
                                       ("a.usd", "usd"), ("scene.xml", "mitsuba-scene"), ("a.brdf", "brdf-explorer"),
                                       ("dir.v2/satin.gltf", "gltf")])
def test_format_from_the_ending(name, fmt):
    assert format_for_output(name) == fmt
    assert resolve_format(None, name) == fmt


def test_every_format_s_own_ending_is_in_the_table():
    table = endings()
    for fmt in FORMATS:
        for ext in format_module(fmt).EXTENSIONS:
            assert fmt in table[ext.lower()]


def test_a_shared_ending_is_an_error_naming_the_formats():
    with pytest.raises(ExportError) as exc:
        format_for_output("satin.bsdf")
    msg = str(exc.value)
    assert "rgl-bsdf and rgl-bsdf-spectral" in msg and "--format" in msg and "\n" not in msg


@pytest.mark.parametrize("name", ["satin.usdc", "satin.png", "satin"])
def test_an_unknown_ending_is_an_error_listing_the_choices(name):
    with pytest.raises(ExportError) as exc:
        format_for_output(name)
    msg = str(exc.value)
    assert "\n" not in msg and "--format" in msg
    for ext, fmts in endings().items():
        assert ext in msg and all(f in msg for f in fmts)


def test_explicit_format_wins_and_a_contradiction_is_an_error():
    assert resolve_format("rgl-bsdf-spectral", "satin.bsdf") == "rgl-bsdf-spectral"
    with pytest.raises(ExportError) as exc:
        resolve_format("gltf", "satin.glb")
    msg = str(exc.value)
    assert msg.startswith("--format gltf: expected an output file ending in .gltf") and "ending of glb" in msg


def test_cli_infers_the_format_and_checks_before_work(tmp_path, kes_model, capsys):
    path = tmp_path / "m.kes.json"
    kes_model.save(path)
    out = tmp_path / "m.brdf"
    assert main(["export", str(path), "-o", str(out)]) == 0
    assert out.is_file() and "exported" in capsys.readouterr().err
    for argv in (["-o", str(tmp_path / "m.bsdf")], ["-o", str(tmp_path / "m.usdc")],
                 ["--format", "gltf", "-o", str(tmp_path / "m.glb")]):
        assert main(["export", str(path), *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("kesbrdf: error:")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.brdf", "m.kes.json"]


@pytest.mark.parametrize("fmt, name", [("mtlx", "m.mtlx"), ("usd", "m.usda")])
def test_mtlx_and_usd_print_their_fit_error_numbers(tmp_path, kes_model, fits, fmt, name):
    pytest.importorskip("MaterialX")
    if fmt == "usd":
        pytest.importorskip("pxr")
    variants = {"mtlx": ("openpbr", "standard_surface"), "usd": ("openpbr",)}[fmt]
    analytic = {v: fits[v] for v in fits if v in ("openpbr", "standard_surface")}
    result = export(kes_model, fmt, tmp_path / name, fits=analytic)
    line = agreement_line(result.agreement)
    assert "\n" not in line and "exact=False" in line
    for v in variants:
        err = fits[v].error
        assert f"nrmse {err['nrmse']:.4g}" in line and f"rel_l1 {err['rel_l1']:.4g}" in line
    assert "; fit;" not in line and "; fit_error;" not in line and not line.startswith("fit;")
