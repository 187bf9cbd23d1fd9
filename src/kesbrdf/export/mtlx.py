"""MaterialX export (format ``mtlx``): OpenPBR Surface and Standard Surface materials.

One ``.mtlx`` document holds two materials fitted to the model by
:func:`kesbrdf.export.analytic_fit.fit_analytic`:

``<name>_openpbr``
    an ``open_pbr_surface`` (:mod:`kesbrdf.export.openpbr`).  OpenPBR has no rotation
    input, so the anisotropy direction is the world tangent rotated about the world
    normal by the fitted angle: ``tangent(world) → rotate3d(axis = normal(world),
    amount = ρ in degrees) → normalize → geometry_tangent``.
``<name>_standard_surface``
    a ``standard_surface`` (:mod:`kesbrdf.export.standard_surface`) whose
    ``specular_rotation`` (turns) carries the rotation.

The mesh tangent must run along the warp (as in the glTF preview meshes).  Each shader
node's ``doc`` string states the fit error (image RMSE, NRMSE, the parameters at a
bound of their range), so the file says that it is an approximation; :func:`export` checks ``doc.validate()`` against the standard
libraries before writing.
"""

from __future__ import annotations

import math
from pathlib import Path

from kesbrdf._atomic import atomic_path
from kesbrdf.errors import KesbrdfError
from kesbrdf.export._framework import ExportResult

__all__ = ["export", "build_document", "load_standard_libraries", "OPEN_WITH", "VARIANTS"]

VARIANTS = ("openpbr", "standard_surface")
OPEN_WITH = (
    "MaterialX Viewer / MaterialX Graph Editor (materialx.org), Autodesk Arnold/Maya, Houdini (Karma), "
    "Omniverse, Blender 4.x (USD import), any OpenPBR- or Standard-Surface-capable MaterialX renderer"
)


def _mx():
    try:
        import MaterialX as mx
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("the mtlx export needs the 'materialx' package: pip install 'kesbrdf[export]'") from exc
    return mx


def load_standard_libraries():
    """The MaterialX standard data libraries (stdlib, pbrlib, bxdf) as a document."""
    mx = _mx()
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _color(mx, v):
    v = list(v) if hasattr(v, "__len__") else [v]
    if len(v) == 1:
        v = v * 3
    return mx.Color3(*[float(a) for a in v[:3]])


def _doc_string(fit) -> str:
    e = fit.error
    bounds = ", ".join(e.get("at_bounds", [])) or "none"
    return (
        f"APPROXIMATION of a kesbrdf extended-KES fabric model: {fit.material} fitted by least squares on displayed "
        f"pixel values (sRGB of x/(1+x), x = pi f cos theta_i, weighted by cos theta_r and a studio light) over the hemisphere, "
        f"every parameter within its physical range. Fit error: image RMSE {e['image_rmse']:.4f} (display units), "
        f"NRMSE {e['nrmse']:.4f} (theta <= 70 deg: {e['nrmse_theta_le_70']:.4f}), relative L1 {e['rel_l1']:.4f}, "
        f"log-RMSE {e['log_rmse']:.4f} over {e['n_pairs']} direction pairs. Parameters at a bound of their range: {bounds}. "
        "Tangent = warp; anisotropy rotation counter-clockwise from the warp about the normal."
    )


def _add_openpbr(mx, doc, name, fit):
    p = fit.params
    sh = doc.addNode("open_pbr_surface", f"{name}_openpbr_shader", "surfaceshader")
    sh.setInputValue("base_weight", 1.0, "float")
    sh.setInputValue("base_color", _color(mx, p["base_color"]), "color3")
    sh.setInputValue("base_diffuse_roughness", 0.0, "float")
    sh.setInputValue("specular_weight", 1.0, "float")
    sh.setInputValue("specular_color", _color(mx, p["specular_color"]), "color3")
    sh.setInputValue("specular_roughness", float(p["specular_roughness"]), "float")
    sh.setInputValue("specular_roughness_anisotropy", float(p["specular_roughness_anisotropy"]), "float")
    sh.setInputValue("specular_ior", float(p["specular_ior"]), "float")
    sh.setInputValue("fuzz_weight", float(p["fuzz_weight"]), "float")
    sh.setInputValue("fuzz_color", _color(mx, p["fuzz_color"]), "color3")
    sh.setInputValue("fuzz_roughness", float(p["fuzz_roughness"]), "float")
    # rotated tangent: OpenPBR has no rotation input
    tangent = doc.addNode("tangent", f"{name}_tangent", "vector3")
    tangent.setInputValue("space", "world", "string")
    normal = doc.addNode("normal", f"{name}_normal", "vector3")
    normal.setInputValue("space", "world", "string")
    rot = doc.addNode("rotate3d", f"{name}_tangent_rotate", "vector3")
    rot.setConnectedNode("in", tangent)
    rot.setInputValue("amount", math.degrees(float(p["tangent_rotation"])), "float")
    rot.setConnectedNode("axis", normal)
    norm = doc.addNode("normalize", f"{name}_tangent_normalize", "vector3")
    norm.setConnectedNode("in", rot)
    sh.setConnectedNode("geometry_tangent", norm)
    sh.setDocString(_doc_string(fit))
    doc.addMaterialNode(f"{name}_openpbr", sh)


def _add_standard_surface(mx, doc, name, fit):
    p = fit.params
    sh = doc.addNode("standard_surface", f"{name}_standard_surface_shader", "surfaceshader")
    sh.setInputValue("base", 1.0, "float")
    sh.setInputValue("base_color", _color(mx, p["base_color"]), "color3")
    sh.setInputValue("diffuse_roughness", 0.0, "float")
    sh.setInputValue("specular", 1.0, "float")
    sh.setInputValue("specular_color", _color(mx, p["specular_color"]), "color3")
    sh.setInputValue("specular_roughness", float(p["specular_roughness"]), "float")
    sh.setInputValue("specular_anisotropy", float(p["specular_anisotropy"]), "float")
    sh.setInputValue("specular_rotation", float(p["specular_rotation"]), "float")
    sh.setInputValue("specular_IOR", float(p["specular_IOR"]), "float")
    sh.setInputValue("sheen", float(p["sheen"]), "float")
    sh.setInputValue("sheen_color", _color(mx, p["sheen_color"]), "color3")
    sh.setInputValue("sheen_roughness", float(p["sheen_roughness"]), "float")
    sh.setDocString(_doc_string(fit))
    doc.addMaterialNode(f"{name}_standard_surface", sh)


def build_document(fits: dict, name: str = "kesbrdf_fabric"):
    """A MaterialX document with one material per fit in ``fits`` (keys: variant names).

    Returns
    -------
    (doc, libraries)
        ``doc`` has the standard libraries set as its data library (not written).
    """
    mx = _mx()
    lib = load_standard_libraries()
    doc = mx.createDocument()
    doc.setDataLibrary(lib)
    doc.setDocString("kesbrdf export: analytic approximations of a measured fabric BRDF; see each shader's doc for its fit error")
    if "openpbr" in fits:
        _add_openpbr(mx, doc, name, fits["openpbr"])
    if "standard_surface" in fits:
        _add_standard_surface(mx, doc, name, fits["standard_surface"])
    return doc, lib


#: File endings ``kesbrdf export`` accepts for this format (checked before any work).
EXTENSIONS = (".mtlx",)
HELP = 'MaterialX document: fitted OpenPBR Surface and Autodesk Standard Surface materials'


def export(model, out, *, variants=VARIANTS, fits: dict | None = None, fit_grid=None, error_grid=None, name: str = "kesbrdf_fabric") -> ExportResult:
    """Write ``model``'s OpenPBR and Standard Surface fits to a ``.mtlx`` file.

    Parameters
    ----------
    variants : sequence of {"openpbr", "standard_surface"}
    fits : dict, optional
        Precomputed :class:`~kesbrdf.export.analytic_fit.AnalyticFit` per variant.

    Returns
    -------
    ExportResult
        ``agreement``: ``materials``, ``fit`` and ``fit_error`` per variant, ``exact``.
    """
    from kesbrdf.export.analytic_fit import ERROR_GRID, FIT_GRID, fit_analytic
    from kesbrdf.export.gltf import agreement_numbers
    from kesbrdf.export.openpbr import OPENPBR
    from kesbrdf.export.standard_surface import STANDARD_SURFACE

    mx = _mx()
    out = Path(out)
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown or not variants:
        raise KesbrdfError(f"mtlx export: expected variants among {', '.join(VARIANTS)}, got {list(variants)!r}")
    materials = {"openpbr": OPENPBR, "standard_surface": STANDARD_SURFACE}
    fits = dict(fits or {})
    for v in variants:
        if v not in fits:
            fits[v] = fit_analytic(materials[v], model, grid=fit_grid or FIT_GRID, error_grid=error_grid or ERROR_GRID)
    fits = {v: fits[v] for v in variants}
    doc, _lib = build_document(fits, name)
    ok, message = doc.validate()
    if not ok:  # pragma: no cover - a bug in this module, not user input
        raise KesbrdfError(f"mtlx export: MaterialX rejected the document: {message}")
    with atomic_path(out) as tmp:
        options = mx.XmlWriteOptions()
        options.writeXIncludeEnable = False
        mx.writeToXmlFile(doc, str(tmp), options)
    agreement = {
        "materials": [f"{name}_{v}" for v in variants],
        "fit": {v: f.as_dict() for v, f in fits.items()},
        "fit_error": {v: agreement_numbers(f) for v, f in fits.items()},
        "exact": False,
    }
    return ExportResult("mtlx", [out], size=out.stat().st_size, agreement=agreement, open_with=OPEN_WITH)
