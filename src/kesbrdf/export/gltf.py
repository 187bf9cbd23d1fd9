"""glTF 2.0 export (formats ``gltf`` and ``glb``): the fitted material on preview meshes.

The file holds one material (core metallic-roughness plus ``KHR_materials_anisotropy``,
``KHR_materials_sheen``, ``KHR_materials_specular`` and ``KHR_materials_ior``, fitted by
:func:`kesbrdf.export.analytic_fit.fit_analytic` against
:class:`kesbrdf.export.gltf_pbr.GltfPbr`), used by two meshes with NORMAL, TANGENT
(along the warp, w = +1) and TEXCOORD_0: a swatch and a sphere
(:mod:`kesbrdf.export.preview_mesh`), side by side in one scene.  The fit error
(image RMSE, NRMSE, relative L1, worst configurations, parameters at a bound of their
range) is written in ``material.extras.kesbrdf`` so nobody mistakes the approximation
for the measurement.

``KHR_materials_ior`` carries the fitted index (in textile fibres' range 1.3–1.8;
its F0 is the brightest channel's) and ``specularColorFactor`` (≤ 1) tints the other
channels; ``specularFactor`` is 1, so F90 = 1 in every importer
(:class:`kesbrdf.export.gltf_pbr.GltfPbr`).  The per-channel F0 and its equivalent
index are written for information in ``extras.kesbrdf.specular``.

``.gltf`` embeds the buffer as a base64 data URI (one self-contained file);
``.glb`` is the binary container.  Written with ``pygltflib``.
"""

from __future__ import annotations

import base64
import math
from pathlib import Path

import numpy as np

from kesbrdf._atomic import atomic_path
from kesbrdf.errors import KesbrdfError
from kesbrdf.export._framework import ExportResult

__all__ = ["export", "build_gltf", "fit_error_record", "agreement_numbers", "OPEN_WITH"]

OPEN_WITH = (
    "any glTF 2.0 viewer with KHR_materials_anisotropy/sheen/specular/ior: Khronos glTF Sample Viewer "
    "(github.khronos.org/glTF-Sample-Viewer-Release, drag and drop), three.js GLTFLoader, "
    "Blender (File > Import > glTF 2.0), Babylon.js Sandbox"
)

_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT = 5126
_UNSIGNED_INT = 5125


def fit_error_record(fit) -> dict:
    """The fit error every analytic export writes into its file: image-space and BRDF-space
    numbers, their definitions and the parameters that ended at a bound of their range."""
    e = fit.error
    return {
        "image_rmse": e["image_rmse"],
        "nrmse": e["nrmse"],
        "nrmse_theta_le_70": e["nrmse_theta_le_70"],
        "rel_l1": e["rel_l1"],
        "log_rmse": e["log_rmse"],
        "at_bounds": list(e.get("at_bounds", [])),
        "image_definition": e.get("image_definition", ""),
        "definition": e["definition"],
    }


def _fit_extras(fit) -> dict:
    return {
        "kesbrdf": {
            "note": "APPROXIMATION: analytic glTF material fitted to the kesbrdf model; not the measurement",
            "fit_error": {**fit_error_record(fit), "worst": fit.error["worst"]},
            "weighting": fit.weighting,
            "grid": fit.grid,
            "basins": fit.basins,
            "tangent_convention": "TANGENT = warp (fabric x), bitangent = NORMAL x TANGENT = weft (w = +1); "
            "anisotropyRotation counter-clockwise from the warp about the normal",
        }
    }


#: Angle (radians) of the constant anisotropyTexture's direction (255, 128) from the
#: tangent: 8 bits cannot store 0 exactly (128/255·2 − 1 = 1/255).  0.22°, far below any
#: fabric lobe's width; written in ``extras.kesbrdf`` for the record.
TEXTURE_DIRECTION_OFFSET = math.atan2(1.0 / 255.0, 1.0)


def _constant_png(rgb) -> bytes:
    """A 1x1 8-bit RGB PNG of colour ``rgb`` (stdlib zlib; no imaging library needed)."""
    import struct
    import zlib

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    raw = b"\0" + bytes(int(c) for c in rgb)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def build_gltf(fit, meshes, model_info: dict | None = None, anisotropy_texture: bool = True):
    """A ``pygltflib.GLTF2`` with the fitted material on ``meshes`` (one node each).

    ``anisotropy_texture`` adds a constant 1x1 ``anisotropyTexture`` (direction = the
    mesh tangent, strength x1): by the extension's text the same material, but Blender's
    importer reads the tangent from the UV map only when there is such a texture, and
    otherwise uses its default radial tangent, off the warp on most meshes
    (docs/exports.md, "Exports in their renderers")."""
    import pygltflib as g

    from kesbrdf.export.gltf_pbr import EXTENSIONS, IOR, equivalent_ior, material_json, specular_f0

    blob = bytearray()
    buffer_views, accessors = [], []

    def add(array, target, kind, component, minmax=False):
        array = np.ascontiguousarray(array)
        offset = len(blob)
        blob.extend(array.tobytes())
        blob.extend(b"\0" * (-len(blob) % 4))
        buffer_views.append(g.BufferView(buffer=0, byteOffset=offset, byteLength=array.nbytes, target=target))
        acc = g.Accessor(bufferView=len(buffer_views) - 1, componentType=component, count=array.shape[0], type=kind)
        if minmax:
            acc.min = [float(a) for a in array.min(axis=0)]
            acc.max = [float(a) for a in array.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    gl_meshes, nodes = [], []
    offsets = np.linspace(-0.75, 0.75, len(meshes)) if len(meshes) > 1 else [0.0]
    for k, m in enumerate(meshes):
        attrs = g.Attributes(
            POSITION=add(m.positions, _ARRAY_BUFFER, "VEC3", _FLOAT, minmax=True),
            NORMAL=add(m.normals, _ARRAY_BUFFER, "VEC3", _FLOAT),
            TANGENT=add(m.tangents, _ARRAY_BUFFER, "VEC4", _FLOAT),
            TEXCOORD_0=add(m.uvs, _ARRAY_BUFFER, "VEC2", _FLOAT),
        )
        indices = add(m.indices, _ELEMENT_ARRAY_BUFFER, "SCALAR", _UNSIGNED_INT)
        gl_meshes.append(g.Mesh(name=m.name, primitives=[g.Primitive(attributes=attrs, indices=indices, material=0)]))
        nodes.append(g.Node(name=m.name, mesh=k, translation=[float(offsets[k]), 0.0, 0.0]))
    extras = _fit_extras(fit)
    f0 = specular_f0(fit.params)
    extras["kesbrdf"]["specular"] = {
        "ior": float(fit.params.get("ior", IOR)),
        "f0": f0,
        "equivalent_ior": equivalent_ior(f0),
        "note": "F0 per channel = min(((ior-1)/(ior+1))^2 * specularColorFactor, 1) * specularFactor; "
        "specularFactor 1 and specularColorFactor <= 1 so that importers agree (docs/exports.md); "
        "equivalent_ior = (1+sqrt(F0))/(1-sqrt(F0)) per channel is informative",
    }
    if model_info:
        extras["kesbrdf"]["model"] = model_info
    mj = material_json(fit.params, extras=extras)
    textures = {}
    if anisotropy_texture:
        # a 1x1 constant anisotropyTexture (direction (1, 0) = the mesh tangent, strength x1):
        # the same material by the extension's text, but importers that ignore TANGENT without
        # a texture (Blender's takes the tangent from the UV map only then) follow the warp
        png = _constant_png((255, 128, 255))
        view = len(buffer_views)
        offset = len(blob)
        blob.extend(png)
        blob.extend(b"\0" * (-len(blob) % 4))
        buffer_views.append(g.BufferView(buffer=0, byteOffset=offset, byteLength=len(png)))
        textures = {"images": [g.Image(bufferView=view, mimeType="image/png", name="anisotropy_warp")],
                    "samplers": [g.Sampler(magFilter=9728, minFilter=9728)],
                    "textures": [g.Texture(sampler=0, source=0, name="anisotropy_warp")]}
        mj["extensions"]["KHR_materials_anisotropy"]["anisotropyTexture"] = {"index": 0, "texCoord": 0}
        mj["extras"]["kesbrdf"]["anisotropy_texture"] = (
            "constant (255, 128, 255): direction = TANGENT (offset "
            f"{math.degrees(TEXTURE_DIRECTION_OFFSET):.2f} deg from 8-bit rounding), strength x1; "
            "present so that importers which ignore TANGENT without a texture (Blender) follow the UV map")
    material = g.Material(**_material_kwargs(mj))
    gltf = g.GLTF2(
        **textures,
        asset=g.Asset(version="2.0", generator="kesbrdf export"),
        scene=0,
        scenes=[g.Scene(name="kesbrdf preview", nodes=list(range(len(nodes))))],
        nodes=nodes,
        meshes=gl_meshes,
        materials=[material],
        accessors=accessors,
        bufferViews=buffer_views,
        buffers=[g.Buffer(byteLength=len(blob))],
        extensionsUsed=list(EXTENSIONS),
    )
    return gltf, bytes(blob)


def _material_kwargs(mj: dict) -> dict:
    import pygltflib as g

    pbr = mj["pbrMetallicRoughness"]
    return {
        "name": mj["name"],
        "pbrMetallicRoughness": g.PbrMetallicRoughness(
            baseColorFactor=pbr["baseColorFactor"], metallicFactor=pbr["metallicFactor"], roughnessFactor=pbr["roughnessFactor"]
        ),
        "extensions": mj["extensions"],
        "extras": mj.get("extras", {}),
    }


def agreement_numbers(fit) -> dict:
    """The short agreement record of an analytic fit: image RMSE, NRMSE, rel. L1, bounds hit."""
    e = fit.error
    return {"image_rmse": e["image_rmse"], "nrmse": e["nrmse"], "rel_l1": e["rel_l1"], "at_bounds": list(e.get("at_bounds", []))}


def _model_info(model) -> dict:
    info = {"kind": getattr(model, "kind", type(model).__name__)}
    channels = getattr(model, "channels", None)
    if channels is not None:
        info["channels"] = list(channels)
    return info


#: File endings ``kesbrdf export`` accepts for this format (checked before any work).
EXTENSIONS = (".gltf",)
HELP = 'glTF 2.0 (JSON + embedded buffer): fitted metallic-roughness + KHR anisotropy/sheen/specular/ior on a swatch and a sphere'


def export(model, out, *, binary: bool | None = None, fit=None, fit_grid=None, error_grid=None) -> ExportResult:
    """Write ``model``'s fitted glTF material on a swatch and a sphere to ``out``.

    Parameters
    ----------
    model : Model or callable
        Anything :func:`kesbrdf.export.analytic_fit.fit_analytic` accepts.
    out : path
        ``.gltf`` (JSON, embedded buffer) or ``.glb`` (binary); ``binary`` overrides.
    fit : AnalyticFit, optional
        A glTF fit already computed (the fit is the slow part; the CLI shares it).

    Returns
    -------
    ExportResult
        ``agreement``: ``fit`` (params and error), ``fit_error`` (image RMSE, NRMSE,
        rel. L1, bounds hit), ``exact`` (False: a fitted approximation).
    """
    from kesbrdf.export.analytic_fit import ERROR_GRID, FIT_GRID, fit_analytic
    from kesbrdf.export.gltf_pbr import GLTF_PBR
    from kesbrdf.export.preview_mesh import swatch, uv_sphere

    out = Path(out)
    if binary is None:
        if out.suffix.lower() not in (".gltf", ".glb"):
            raise KesbrdfError(f"glTF export: expected an output ending in .gltf or .glb, got {out.name!r}")
        binary = out.suffix.lower() == ".glb"
    if fit is None:
        fit = fit_analytic(GLTF_PBR, model, grid=fit_grid or FIT_GRID, error_grid=error_grid or ERROR_GRID)
    elif fit.material != GLTF_PBR.name:
        raise KesbrdfError(f"glTF export: expected a {GLTF_PBR.name!r} fit, got {fit.material!r}")
    gltf, blob = build_gltf(fit, [swatch(1.0), uv_sphere(0.5)], _model_info(model))
    with atomic_path(out) as tmp:
        if binary:
            gltf.set_binary_blob(blob)
            gltf.save_binary(str(tmp))
        else:
            gltf.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode("ascii")
            gltf.save_json(str(tmp))
    return ExportResult("glb" if binary else "gltf", [out], size=out.stat().st_size,
                        agreement={"fit": fit.as_dict(), "fit_error": agreement_numbers(fit), "exact": False},
                        open_with=OPEN_WITH)
