"""USD export (format ``usd``): a ``.usda`` stage with the fitted fabric material bound to previews.

The stage (written with ``usd-core``) holds

- ``/Looks/kesbrdf_fabric``: a ``UsdShade.Material`` (``customData`` holds both fits'
  errors and the parameters that ended at a bound) with two surface outputs:

  * ``outputs:mtlx:surface`` → an OpenPBR Surface network in the USD encoding of
    MaterialX (``info:id = "ND_open_pbr_surface_surfaceshader"``, the tangent rotated by
    ``ND_rotate3d_vector3`` about the world normal), the form Houdini/Karma, Omniverse
    and usdview's Storm read; the same material is written to the sidecar ``.mtlx``
    (:mod:`kesbrdf.export.mtlx`), named in the material's ``customData``;
  * ``outputs:surface`` → a ``UsdPreviewSurface`` fallback for every other renderer:
    isotropic, so coarser, but fitted to the model in its own right
    (:mod:`kesbrdf.export.preview_surface`: diffuseColor, roughness and an ior in
    textile fibres' range 1.3–1.8, metallic 0), so it shows the fabric's colour with a
    plausible gloss; the OpenPBR parameters are not copied into it (a bright OpenPBR
    specular layer on a black base would make a grey mirror of a black fabric).

  A reference arc to the ``.mtlx`` itself is not written: it needs the usdMtlx file
  format plugin, which the ``usd-core`` wheel does not ship, and a stage that fails to
  compose in the reference implementation would be a bad export.
- ``/Preview/swatch`` and ``/Preview/sphere``: ``UsdGeom.Mesh`` with normals, ``st`` and
  a ``tangents`` primvar along the warp, bound to the material with
  ``UsdShade.MaterialBindingAPI``.  The stage is y-up, metres.
"""

from __future__ import annotations

import math
from pathlib import Path

from kesbrdf._atomic import atomic_path
from kesbrdf.errors import KesbrdfError
from kesbrdf.export._framework import ExportResult

__all__ = ["export", "OPEN_WITH", "MATERIAL_PATH"]

MATERIAL_PATH = "/Looks/kesbrdf_fabric"
OPEN_WITH = (
    "usdview (OpenUSD), Houdini Solaris/Karma, NVIDIA Omniverse, Blender (File > Import > USD), "
    "Apple Reality Composer/Preview (UsdPreviewSurface fallback)"
)


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt
    except ImportError as exc:  # pragma: no cover
        raise ImportError("the usd export needs the 'usd-core' package: pip install 'kesbrdf[export]'") from exc
    return Gf, Sdf, Usd, UsdGeom, UsdShade, Vt


def _rgb(Gf, v):
    v = list(v) if hasattr(v, "__len__") else [v]
    if len(v) == 1:
        v = v * 3
    return Gf.Vec3f(*[float(a) for a in v[:3]])


def _add_mesh(stage, path, mesh, offset_x, material, Gf, Sdf, UsdGeom, UsdShade, Vt):
    m = UsdGeom.Mesh.Define(stage, path)
    pos = mesh.positions.astype(float).copy()
    pos[:, 0] += offset_x
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pos.astype("float32")))
    m.CreateFaceVertexCountsAttr(Vt.IntArray([3] * (mesh.indices.size // 3)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray(mesh.indices.astype(int).tolist()))
    m.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(mesh.normals))
    m.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    m.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    pv = UsdGeom.PrimvarsAPI(m)
    st = mesh.uvs.astype(float).copy()
    st[:, 1] = 1.0 - st[:, 1]  # glTF v runs down, USD st up
    pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(Vt.Vec2fArray.FromNumpy(st.astype("float32")))
    pv.CreatePrimvar("tangents", Sdf.ValueTypeNames.Float3Array, UsdGeom.Tokens.vertex).Set(Vt.Vec3fArray.FromNumpy(mesh.tangents[:, :3].copy()))
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    m.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(material)
    return m


def _error_data(fit) -> dict:
    e = fit.error
    return {
        "image_rmse": float(e["image_rmse"]), "nrmse": float(e["nrmse"]), "rel_l1": float(e["rel_l1"]),
        "log_rmse": float(e["log_rmse"]), "at_bounds": ", ".join(e.get("at_bounds", [])),
    }


def build_stage(stage, fit, mtlx_name: str | None, preview_fit=None):
    """Define the material and the preview meshes on ``stage`` (an ``Usd.Stage``).

    ``fit`` is the OpenPBR fit; ``preview_fit`` the UsdPreviewSurface fit of the fallback.
    """
    Gf, Sdf, Usd, UsdGeom, UsdShade, Vt = _pxr()
    from kesbrdf.export.preview_mesh import swatch, uv_sphere

    if preview_fit is None or preview_fit.material != "preview_surface":
        raise KesbrdfError("usd export: expected a 'preview_surface' fit for the UsdPreviewSurface fallback")
    p = fit.params
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Preview")
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.Scope.Define(stage, "/Looks")
    material = UsdShade.Material.Define(stage, MATERIAL_PATH)
    e, ep = fit.error, preview_fit.error
    note = (
        f"APPROXIMATION of a kesbrdf extended-KES fabric model. OpenPBR ({fit.material} fit): image RMSE "
        f"{e['image_rmse']:.4f}, NRMSE {e['nrmse']:.4f}; UsdPreviewSurface fallback: image RMSE {ep['image_rmse']:.4f}, "
        f"NRMSE {ep['nrmse']:.4f}; parameters at a bound of their range: "
        f"{', '.join(e.get('at_bounds', [])) or 'none'} / {', '.join(ep.get('at_bounds', [])) or 'none'}; tangent = warp"
    )
    material.GetPrim().SetDocumentation(note)
    material.GetPrim().SetCustomDataByKey("kesbrdf:fit_error", _error_data(fit))
    material.GetPrim().SetCustomDataByKey("kesbrdf:preview_fit_error", _error_data(preview_fit))
    if mtlx_name:
        material.GetPrim().SetCustomDataByKey("kesbrdf:mtlx", Sdf.AssetPath(mtlx_name))

    # MaterialX OpenPBR network (USD encoding of MaterialX nodes)
    sh = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/open_pbr_surface")
    sh.CreateIdAttr("ND_open_pbr_surface_surfaceshader")
    f, c3 = Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Color3f
    sh.CreateInput("base_weight", f).Set(1.0)
    sh.CreateInput("base_color", c3).Set(_rgb(Gf, p["base_color"]))
    sh.CreateInput("base_diffuse_roughness", f).Set(0.0)
    sh.CreateInput("specular_weight", f).Set(1.0)
    sh.CreateInput("specular_color", c3).Set(_rgb(Gf, p["specular_color"]))
    sh.CreateInput("specular_roughness", f).Set(float(p["specular_roughness"]))
    sh.CreateInput("specular_roughness_anisotropy", f).Set(float(p["specular_roughness_anisotropy"]))
    sh.CreateInput("specular_ior", f).Set(float(p["specular_ior"]))
    sh.CreateInput("fuzz_weight", f).Set(float(p["fuzz_weight"]))
    sh.CreateInput("fuzz_color", c3).Set(_rgb(Gf, p["fuzz_color"]))
    sh.CreateInput("fuzz_roughness", f).Set(float(p["fuzz_roughness"]))
    v3 = Sdf.ValueTypeNames.Vector3f
    tangent = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/tangent")
    tangent.CreateIdAttr("ND_tangent_vector3")
    tangent.CreateInput("space", Sdf.ValueTypeNames.String).Set("world")
    normal = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/normal")
    normal.CreateIdAttr("ND_normal_vector3")
    normal.CreateInput("space", Sdf.ValueTypeNames.String).Set("world")
    rot = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/tangent_rotate")
    rot.CreateIdAttr("ND_rotate3d_vector3")
    rot.CreateInput("in", v3).ConnectToSource(tangent.CreateOutput("out", v3))
    rot.CreateInput("amount", f).Set(math.degrees(float(p["tangent_rotation"])))
    rot.CreateInput("axis", v3).ConnectToSource(normal.CreateOutput("out", v3))
    norm = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/tangent_normalize")
    norm.CreateIdAttr("ND_normalize_vector3")
    norm.CreateInput("in", v3).ConnectToSource(rot.CreateOutput("out", v3))
    sh.CreateInput("geometry_tangent", v3).ConnectToSource(norm.CreateOutput("out", v3))
    material.CreateSurfaceOutput("mtlx").ConnectToSource(sh.CreateOutput("surface", Sdf.ValueTypeNames.Token))

    # UsdPreviewSurface fallback (isotropic), fitted in its own right (preview_surface)
    pp = preview_fit.params
    ps = UsdShade.Shader.Define(stage, f"{MATERIAL_PATH}/preview_surface")
    ps.CreateIdAttr("UsdPreviewSurface")
    ps.CreateInput("diffuseColor", c3).Set(_rgb(Gf, pp["diffuse_color"]))
    ps.CreateInput("roughness", f).Set(float(pp["roughness"]))
    ps.CreateInput("metallic", f).Set(0.0)
    ps.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    ps.CreateInput("ior", f).Set(float(pp["ior"]))
    material.CreateSurfaceOutput().ConnectToSource(ps.CreateOutput("surface", Sdf.ValueTypeNames.Token))

    _add_mesh(stage, "/Preview/swatch", swatch(1.0), -0.75, material, Gf, Sdf, UsdGeom, UsdShade, Vt)
    _add_mesh(stage, "/Preview/sphere", uv_sphere(0.5), 0.75, material, Gf, Sdf, UsdGeom, UsdShade, Vt)
    return material


#: File endings ``kesbrdf export`` accepts for this format (checked before any work).
EXTENSIONS = (".usda", ".usd")
HELP = 'USD stage: OpenPBR network + UsdPreviewSurface fallback bound to preview meshes (writes the .mtlx beside it)'


def export(model, out, *, fits: dict | None = None, fit_grid=None, error_grid=None, write_mtlx: bool = True) -> ExportResult:
    """Write a ``.usda`` stage (and, by default, the sidecar ``.mtlx``) for ``model``.

    Returns
    -------
    ExportResult
        ``paths``: the .usda, then the .mtlx; ``agreement``: ``material`` (the prim path),
        ``fit_error`` per fit, ``exact``, ``mtlx_size``.
    """
    from kesbrdf.export.analytic_fit import ERROR_GRID, FIT_GRID, fit_analytic
    from kesbrdf.export.gltf import agreement_numbers
    from kesbrdf.export.openpbr import OPENPBR
    from kesbrdf.export.preview_surface import PREVIEW_SURFACE

    Gf, Sdf, Usd, UsdGeom, UsdShade, Vt = _pxr()
    out = Path(out)
    if out.suffix.lower() not in (".usda", ".usd"):
        raise KesbrdfError(f"usd export: expected an output ending in .usda (or .usd, written as text), got {out.name!r}")
    fits = dict(fits or {})
    for material in (OPENPBR, PREVIEW_SURFACE):
        if material.name not in fits:
            fits[material.name] = fit_analytic(material, model, grid=fit_grid or FIT_GRID, error_grid=error_grid or ERROR_GRID)
    paths = [str(out)]
    mtlx_name = None
    result_extra = {}
    if write_mtlx:
        from kesbrdf.export import mtlx

        mtlx_path = out.with_suffix(".mtlx")
        res = mtlx.export(model, mtlx_path, fits={k: v for k, v in fits.items() if k in mtlx.VARIANTS},
                          fit_grid=fit_grid, error_grid=error_grid)
        mtlx_name = "./" + mtlx_path.name
        paths.append(str(mtlx_path))
        result_extra["mtlx_size"] = res.size
    with atomic_path(out) as tmp:
        layer = Sdf.Layer.CreateAnonymous(".usda")
        stage = Usd.Stage.Open(layer)
        build_stage(stage, fits["openpbr"], mtlx_name, fits["preview_surface"])
        tmp.write_text(layer.ExportToString())
    agreement = {
        "material": MATERIAL_PATH,
        "fit_error": {"openpbr": agreement_numbers(fits["openpbr"]), "preview_surface": agreement_numbers(fits["preview_surface"])},
        "exact": False,
        **result_extra,
    }
    return ExportResult("usd", [Path(p) for p in paths], size=out.stat().st_size, agreement=agreement,
                        open_with=OPEN_WITH)
