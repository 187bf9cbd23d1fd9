"""MaterialX and USD exports, checked by the reference implementations (materialx, usd-core)."""

from __future__ import annotations

import pytest

mx = pytest.importorskip("MaterialX")

from kesbrdf.errors import KesbrdfError  # noqa: E402
from kesbrdf.export import mtlx  # noqa: E402


def _read(path):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    doc.setDataLibrary(mtlx.load_standard_libraries())
    return doc


def test_mtlx_validates_against_the_standard_libraries(tmp_path, kes_model, fits):
    out = tmp_path / "fabric.mtlx"
    res = mtlx.export(kes_model, out, fits=fits)
    doc = _read(out)
    ok, message = doc.validate()
    assert ok, message
    names = {m.getName() for m in doc.getMaterialNodes()}
    assert names == {"kesbrdf_fabric_openpbr", "kesbrdf_fabric_standard_surface"} == set(res.agreement["materials"])
    opbr = doc.getNode("kesbrdf_fabric_openpbr_shader")
    assert opbr.getCategory() == "open_pbr_surface"
    assert opbr.getNodeDefString() == "" and opbr.getNodeDef().getName() == "ND_open_pbr_surface_surfaceshader"
    assert doc.getNode("kesbrdf_fabric_standard_surface_shader").getNodeDef().getName() == "ND_standard_surface_surfaceshader"
    # fitted values and the fit error made it into the file
    assert opbr.getInputValue("fuzz_roughness") == pytest.approx(fits["openpbr"].params["fuzz_roughness"], rel=1e-5)
    assert f"NRMSE {fits['openpbr'].error['nrmse']:.4f}" in opbr.getDocString()
    assert f"image RMSE {fits['openpbr'].error['image_rmse']:.4f}" in opbr.getDocString()
    assert "Parameters at a bound of their range: " + (", ".join(fits["openpbr"].error["at_bounds"]) or "none") in opbr.getDocString()
    assert "APPROXIMATION" in opbr.getDocString()
    rotate = doc.getNode("kesbrdf_fabric_tangent_rotate")
    import math

    assert rotate.getInputValue("amount") == pytest.approx(math.degrees(fits["openpbr"].params["tangent_rotation"]), rel=1e-5)


def test_materialx_validation_can_fail(kes_model, fits):
    """The check is real: a wrongly typed input makes the same validator return False."""
    doc, _ = mtlx.build_document({"openpbr": fits["openpbr"]})
    doc.getNode("kesbrdf_fabric_openpbr_shader").setInputValue("fuzz_weight", "heavy", "string")
    assert doc.validate()[0] is False


def test_materialx_glsl_generation(kes_model, fits):
    """MaterialXGenGlsl generates a fragment shader for both materials (a renderer-side check)."""
    gen = pytest.importorskip("MaterialX.PyMaterialXGenGlsl")
    from MaterialX import PyMaterialXGenShader as mx_gen_shader

    doc, lib = mtlx.build_document(fits)
    generator = gen.GlslShaderGenerator.create()
    context = mx_gen_shader.GenContext(generator)
    context.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    for m in doc.getMaterialNodes():
        shader = generator.generate(m.getName(), m, context)
        assert "void main" in shader.getSourceCode("pixel")


def test_mtlx_rejects_unknown_variant(tmp_path, kes_model, fits):
    with pytest.raises(KesbrdfError, match="variants"):
        mtlx.export(kes_model, tmp_path / "x.mtlx", variants=("disney",), fits=fits)


def test_usd_stage_opens_with_the_material_bound(tmp_path, kes_model, fits):
    pxr = pytest.importorskip("pxr")
    from pxr import Usd, UsdShade

    from kesbrdf.export import usd

    out = tmp_path / "fabric.usda"
    res = usd.export(kes_model, out, fits=fits)
    assert (tmp_path / "fabric.mtlx").exists() and res.paths[1].name == "fabric.mtlx"
    stage = Usd.Stage.Open(str(out))
    assert stage is not None
    for prim_path in ("/Preview/swatch", "/Preview/sphere"):
        prim = stage.GetPrimAtPath(prim_path)
        bound, _rel = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert bound and str(bound.GetPath()) == usd.MATERIAL_PATH
        assert prim.GetAttribute("primvars:tangents").Get() is not None
    material = UsdShade.Material(stage.GetPrimAtPath(usd.MATERIAL_PATH))
    mtlx_surface = material.ComputeSurfaceSource("mtlx")[0]
    assert mtlx_surface.GetIdAttr().Get() == "ND_open_pbr_surface_surfaceshader"
    assert material.ComputeSurfaceSource()[0].GetIdAttr().Get() == "UsdPreviewSurface"
    assert material.GetPrim().GetCustomDataByKey("kesbrdf:fit_error")["nrmse"] == pytest.approx(fits["openpbr"].error["nrmse"])
    # composition produced no errors (e.g. unresolvable references)
    assert list(stage.GetCompositionErrors()) == []
    del pxr
