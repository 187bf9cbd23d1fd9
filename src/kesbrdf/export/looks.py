r"""Each export's look, measured in the renderer that reads it.

An export that *opens* in its tool (the validators of ``tests/export``) can still
*look* wrong there: the tool maps the file's parameters onto its own shading model.
This module renders one studio scene in the target's own renderer and compares the
image with the kesbrdf Mitsuba plugin's render of the model itself:

================  =================================================================
format            renderer (what reads the file)
================  =================================================================
``rgl-bsdf``      Mitsuba 3 ``measured`` (the RGL tensor reader)
``gltf/glb``      Blender Cycles, material from Blender's glTF importer
                  (``bpy.ops.import_scene.gltf``)
``usd``           Blender Cycles, material from Blender's USD importer
                  (``bpy.ops.wm.usd_import``: the ``UsdPreviewSurface``)
``mtlx``          Blender Cycles, Principled BSDF with the ``open_pbr_surface`` inputs
                  read from the ``.mtlx`` (Blender 4.5 imports no MaterialX; mapping in
                  :func:`openpbr_to_principled`)
``gltf-threejs``  the glTF/glb in three.js: ``MeshPhysicalMaterial`` from its
                  ``GLTFLoader``, WebGL in headless Chromium (:func:`threejs_render`;
                  direct light only, soft boxes as grids of point lights)
================  =================================================================

Scene (:func:`studio_scene`, y-up, metres): a UV sphere (warp along the parallels)
and the procedural folded cloth (:func:`kesbrdf.render.mesh.folded_cloth`, warp across
the folds) side by side on a grey floor (:data:`LOOK_FLOOR_ALBEDO`),
under the four soft boxes of :mod:`kesbrdf.render.studio`, no environment; the camera
of :mod:`kesbrdf.render.scenes` (vertical FOV :data:`~kesbrdf.render.scenes.FOV_DEG`)
looks at the pair from the front and above.  Both renderers get the same triangles,
normals and UVs (u = warp), the same emitters and camera (the mapping is in
:mod:`kesbrdf.export.blender_look`: an emissive quad of strength 1 has radiance equal
to its colour, as Mitsuba's ``area`` emitter), paths of at most
:data:`MAX_DEPTH` segments (Cycles ``max_bounces`` = depth − 2), a one-pixel box filter,
no clamping, and Open Image Denoise on both (Mitsuba: ``kesbrdf.render.post.denoise``
with albedo and normal AOVs; Cycles: its built-in OIDN with the same guides).

Numbers (:func:`kesbrdf.render.compare.compare_images`, on the fabric pixels):
**FLIP** of the displayed sRGB images (one exposure, chosen on the plugin render so
its 99.5th-percentile fabric luminance shows at 0.9) and **relative RMSE** of the
linear images, ‖E − P‖₂/‖P‖₂.  The **noise floor** is the same pair of numbers
between two plugin renders with different seeds: an export at the floor looks like
the model as far as this scene can tell.  :func:`direction_mask` narrows the fabric to
the pixels where the anisotropy direction shows (the plugin render changes when the
warp is turned by 90°); over the whole frame a wrong direction is lost among the diffuse
areas and the fit error (``compare_export(..., mask=...)``).

Blender runs in a subprocess (:mod:`kesbrdf.export.blender_look`); ``bpy`` is needed
only there and only then (``pip install 'kesbrdf[blender]'``).  three.js runs in
headless Chromium through node (``viewer/scripts/gltf-look.mjs``, the viewer's npm
packages); without chromium or ``viewer/node_modules`` its row is skipped.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from kesbrdf._drjit import load_dict as _load_dict
from kesbrdf._atomic import atomic_path, write_text
from kesbrdf.errors import ExportError, KesbrdfError

__all__ = [
    "RENDERERS",
    "LookOptions",
    "studio_scene",
    "render_plugin",
    "render_export",
    "blender_render",
    "threejs_render",
    "threejs_lights",
    "RendererMissing",
    "openpbr_to_principled",
    "read_openpbr",
    "check_look",
    "require_renderer",
    "PluginReference",
    "turned_warp_scene",
    "direction_mask",
    "compare_export",
    "check_looks",
    "look_line",
    "write_side_by_side",
]

#: Format -> the renderer that draws it here.
RENDERERS = {
    "rgl-bsdf": "Mitsuba 3 measured",
    "gltf": "Blender Cycles (glTF importer)",
    "glb": "Blender Cycles (glTF importer)",
    "usd": "Blender Cycles (USD importer, UsdPreviewSurface)",
    "mtlx": "Blender Cycles (Principled BSDF from the .mtlx open_pbr_surface)",
    "gltf-threejs": "three.js MeshPhysicalMaterial (GLTFLoader, headless Chromium)",
}
#: Longest light path (segments, Mitsuba's ``max_depth``): direct light and two bounces.
MAX_DEPTH = 4
#: Seconds a Blender render may take before it is abandoned (a hung subprocess).
BLENDER_TIMEOUT_S = 600
#: Sphere radius and folded-cloth size of the scene (metres).
SPHERE_RADIUS = 0.45
CLOTH_SIZE = 1.0
#: Camera direction from the scene centre (y up, camera on +z), as the render scenes.
VIEW_DIR = (0.0, 0.55, 1.0)
#: Camera distance: the bounding sphere's radius times this fills the vertical field of
#: view (the render scenes use 0.95; the pair of objects is wider than tall, so closer).
FRAMING = 0.7


class LookOptions:
    """Resolution, samples and seed of a look check (small: it runs in the demo)."""

    def __init__(self, resolution=(256, 192), spp: int = 32, blender_spp: int = 32, seed: int = 0,
                 denoise: bool = True, threads: int = 2):
        self.resolution = (int(resolution[0]), int(resolution[1]))
        self.spp = int(spp)
        self.blender_spp = int(blender_spp)
        self.seed = int(seed)
        self.denoise = bool(denoise)
        self.threads = int(threads)
        if min(self.resolution) <= 0 or self.spp <= 0 or self.blender_spp <= 0:
            raise KesbrdfError(f"look: expected positive resolution and samples, got {resolution}, {spp}, {blender_spp}")

    def to_json(self) -> dict:
        return {"resolution": list(self.resolution), "spp": self.spp, "blender_spp": self.blender_spp,
                "seed": self.seed, "denoise": self.denoise, "max_depth": MAX_DEPTH}


# -- the scene ---------------------------------------------------------------------------
def _sphere(center, radius, n_u: int = 64, n_v: int = 32):
    """UV sphere, u = φ/2π around +y (the warp along the parallels), v from the bottom up,
    ∂p/∂u × ∂p/∂v along the outward normal (:mod:`kesbrdf.render.mesh` convention)."""
    from kesbrdf.render.mesh import grid_faces

    u, v = np.meshgrid(np.linspace(0, 1, n_u + 1), np.linspace(0, 1, n_v + 1), indexing="ij")
    phi, theta = 2 * math.pi * u, math.pi * (1 - v)
    n = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1).reshape(-1, 3)
    p = np.asarray(center, float) + radius * n
    faces = grid_faces(n_u + 1, n_v + 1)
    # drop the zero-area triangles at the poles
    P = p[faces]
    area = np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=-1)
    return p, n, np.stack([u, v], -1).reshape(-1, 2), faces[area > 1e-12]


#: The look scene's own soft boxes: (name, direction from the subject, distance / r,
#: (width, height) / r, radiance relative to KEY_RADIANCE).  The look check is an
#: instrument, so its light is fixed here and not the demo studio's
#: (:data:`kesbrdf.render.studio.STUDIO_LIGHTS`, tuned for photographs of satin): the
#: bounds in tests/export/test_looks.py were measured under these lights.
LOOK_LIGHTS = (
    ("key", (-0.55, 0.55, 0.80), 3.2, (1.3, 1.7), 1.0),
    ("fill", (0.85, 0.15, 0.55), 3.5, (1.8, 1.8), 0.22),
    ("rim", (0.35, 1.0, -0.60), 3.0, (0.35, 2.2), 1.6),
    ("top", (0.0, 1.0, 0.1), 3.0, (1.6, 1.6), 0.35),
)
#: The look scene's floor albedo (mid grey; fixed for the same reason).
LOOK_FLOOR_ALBEDO = (0.14, 0.14, 0.145)


def studio_scene(resolution=(256, 192)) -> dict:
    """The look scene, renderer-neutral (see the module docstring).

    Returns
    -------
    dict
        ``objects``: {name: (positions, normals, uvs, faces)} with ``sphere`` and
        ``cloth`` (the fabric) and ``floor``; ``lights``: [(corners (4, 3), radiance)];
        ``camera``: origin, target, ``fov_y_deg``; ``center``, ``radius``, ``resolution``.
    """
    from kesbrdf.render import mesh as _mesh
    from kesbrdf.render.scenes import FOV_DEG
    from kesbrdf.render.studio import KEY_RADIANCE

    p, n, uv, f = _mesh.folded_cloth(size=CLOTH_SIZE, n=49)
    floor_y = float(p[:, 1].min())
    p = p + [0.55, 0.0, 0.0]
    cloth = (p, n, uv, f)
    sphere = _sphere((-0.55, floor_y + SPHERE_RADIUS, 0.0), SPHERE_RADIUS)
    allp = np.concatenate([cloth[0], sphere[0]])
    lo, hi = allp.min(0), allp.max(0)
    center = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    s = max(8 * radius, 12.0)
    floor_p = np.array([[-s, floor_y - 1e-3, s], [s, floor_y - 1e-3, s], [s, floor_y - 1e-3, -s], [-s, floor_y - 1e-3, -s]])
    floor_p[:, [0, 2]] += center[[0, 2]]
    floor = (floor_p, np.tile([0.0, 1.0, 0.0], (4, 1)), np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float),
             np.array([[0, 1, 2], [0, 2, 3]], np.uint32))
    lights = []
    for _name, direction, dist, (w, h), rel in LOOK_LIGHTS:
        d = np.asarray(direction, float)
        d /= np.linalg.norm(d)
        origin = center + dist * radius * d
        lights.append((_rectangle_corners(origin, center, (w * radius, h * radius)), [rel * v for v in KEY_RADIANCE]))
    w, h = (int(v) for v in resolution)
    fov = FOV_DEG if w >= h else math.degrees(2 * math.atan(math.tan(math.radians(FOV_DEG * w / h) / 2) * h / w))
    fov_for_dist = FOV_DEG if w >= h else FOV_DEG * w / h
    view = np.asarray(VIEW_DIR, float) / np.linalg.norm(VIEW_DIR)
    dist = FRAMING * radius / math.sin(math.radians(fov_for_dist) / 2)
    return {
        "objects": {"sphere": sphere, "cloth": cloth, "floor": floor},
        "fabric": ("sphere", "cloth"),
        "floor_albedo": list(LOOK_FLOOR_ALBEDO),
        "lights": lights,
        "camera": {"origin": (center + dist * view).tolist(), "target": center.tolist(), "fov_y_deg": fov},
        "center": center.tolist(),
        "radius": radius,
        "resolution": [w, h],
    }


def _rectangle_corners(origin, target, size, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Corners of Mitsuba's ``rectangle`` with ``look_at_rectangle``'s transform, CCW seen
    from the lit side (local (±1, ±1, 0) through look_at(origin → target) and a scale)."""
    o = np.asarray(origin, float)
    fwd = np.asarray(target, float) - o
    fwd /= np.linalg.norm(fwd)
    u = np.asarray(up, float)
    if abs(np.dot(fwd, u)) > 0.99:
        u = np.array([0.0, 0.0, -1.0])
    left = np.cross(u, fwd)
    left /= np.linalg.norm(left)
    new_up = np.cross(fwd, left)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * 0.5 * np.asarray(size, float)
    return o + local[:, :1] * left + local[:, 1:] * new_up


# -- Mitsuba -------------------------------------------------------------------------------
def _mitsuba_scene(scene: dict, fabric_bsdf: dict, opts: LookOptions, seed: int, workdir: Path):
    import mitsuba as mi

    import kesbrdf.render  # noqa: F401  (variant and plugins)
    from kesbrdf.io.ply import write_ply

    d = {"type": "scene"}
    for name, (p, n, uv, f) in scene["objects"].items():
        path = workdir / f"{name}.ply"
        write_ply(path, p, f, n, uv)
        bsdf = fabric_bsdf if name in scene["fabric"] else {
            "type": "diffuse", "reflectance": {"type": "rgb", "value": scene["floor_albedo"]}}
        d[name] = {"type": "ply", "filename": str(path), "bsdf": bsdf}
    for k, (corners, radiance) in enumerate(scene["lights"]):
        c = np.asarray(corners, float)
        center = c.mean(0)
        ex, ey = 0.5 * (c[1] - c[0]), 0.5 * (c[3] - c[0])
        nz = np.cross(ex, ey)
        nz /= np.linalg.norm(nz)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = ex, ey, nz, center
        d[f"light_{k}"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(m.tolist()),
                           "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(map(float, radiance))}}}
    cam = scene["camera"]
    w, h = scene["resolution"]
    d["sensor"] = {
        "type": "perspective", "fov": float(cam["fov_y_deg"]), "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=cam["origin"], target=cam["target"], up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": int(w), "height": int(h), "pixel_format": "rgb", "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": opts.spp, "seed": int(seed)},
    }
    integ = {"type": "path", "max_depth": MAX_DEPTH}
    if opts.denoise:
        integ = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal", "integrator": integ}
    d["integrator"] = integ
    return _load_dict(d)


def _fabric_mask(sc, names) -> np.ndarray:
    """(H, W) bool: the primary ray through each pixel centre hits a fabric object."""
    import drjit as dr
    import mitsuba as mi

    sensor = sc.sensors()[0]
    w, h = (int(v) for v in sensor.film().size())
    idx = dr.arange(mi.UInt32, w * h)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((mi.Float(idx % w) + 0.5) / w, (mi.Float(idx // w) + 0.5) / h),
                               mi.Point2f(0.5))
    si = sc.ray_intersect(ray)
    # Mitsuba merges meshes that share a BSDF into one shape (the fabric objects lose
    # their ids), so the fabric is every hit that is not one of the other, named objects
    hit = np.array(si.is_valid(), bool)
    for s in sc.shapes():
        if s.id() and s.id() not in names:
            hit &= ~np.array(si.shape == mi.ShapePtr(s), bool)
    return hit.reshape(h, w)


def _render_mitsuba(scene: dict, fabric_bsdf: dict, opts: LookOptions, seed: int, want_mask: bool = False):
    import drjit as dr
    import mitsuba as mi

    with tempfile.TemporaryDirectory(prefix="kesbrdf-look-") as tmp:
        sc = _mitsuba_scene(scene, fabric_bsdf, opts, seed, Path(tmp))
        img = mi.render(sc, spp=opts.spp, seed=int(seed))
        dr.eval(img)
        arr = np.array(img, dtype=np.float32)
        mask = _fabric_mask(sc, scene["fabric"]) if want_mask else None
    if opts.denoise and arr.shape[-1] >= 9:
        from kesbrdf.render.post import denoise

        arr = denoise(arr[..., :3], arr[..., 3:6], arr[..., 6:9])
    return arr[..., :3], mask


#: The plugin's lobe beyond the last measured deviation for the reference render: None,
#: the model file's own setting, i.e. the model as :func:`kesbrdf.models.brdf.evaluate` gives it
#: and as every export encodes it (``kesbrdf render`` may override it; no export carries
#: an override).
REFERENCE_EXTRAPOLATION = None


def render_plugin(model_path, scene: dict, opts: LookOptions, seed: int | None = None, want_mask: bool = False):
    """The model itself through its kesbrdf plugin (:func:`kesbrdf.render.scenes.bsdf_dict`),
    extrapolation :data:`REFERENCE_EXTRAPOLATION`."""
    from kesbrdf.render.scenes import RenderOptions, bsdf_dict

    bsdf = bsdf_dict(Path(model_path), RenderOptions(extrapolation=REFERENCE_EXTRAPOLATION))
    return _render_mitsuba(scene, bsdf, opts, opts.seed if seed is None else seed, want_mask)


# -- Blender ---------------------------------------------------------------------------------
class RendererMissing(ExportError):
    """The renderer of a look row is not installed (the row is skipped, the demo goes on)."""


def require_renderer(fmt: str) -> None:
    """A one-line :class:`ExportError` when ``fmt`` has no renderer here or its renderer
    is not installed (checked before any export work)."""
    if fmt not in RENDERERS:
        raise ExportError(f"--check-look: expected a format with a renderer ({', '.join(RENDERERS)}), got {fmt!r}")
    if fmt == "gltf-threejs":
        _require_threejs()
    elif fmt != "rgl-bsdf":
        _require_bpy()


def _require_bpy() -> None:
    if importlib.util.find_spec("bpy") is None:
        raise RendererMissing("the look check in Blender needs the 'bpy' module (Blender 4.5 as a Python module): "
                          "pip install 'kesbrdf[blender]'")


def blender_render(scene: dict, material: dict, opts: LookOptions, workdir) -> tuple[np.ndarray, dict]:
    """Render ``scene`` in Blender Cycles with the fabric ``material`` (see
    :mod:`kesbrdf.export.blender_look` for its forms); returns (linear image, info)."""
    _require_bpy()
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    arrays = {}
    for name, (p, n, uv, f) in scene["objects"].items():
        arrays.update({f"{name}_positions": p, f"{name}_normals": n, f"{name}_uvs": uv, f"{name}_faces": f})
    np.savez(workdir / "meshes.npz", **arrays)
    job = {
        "meshes": str(workdir / "meshes.npz"),
        "objects": [{"name": k, "material": "fabric" if k in scene["fabric"] else "floor"} for k in scene["objects"]],
        "floor_albedo": scene["floor_albedo"],
        "lights": [{"corners": np.asarray(c).tolist(), "radiance": list(r)} for c, r in scene["lights"]],
        "camera": scene["camera"],
        "resolution": scene["resolution"],
        "spp": opts.blender_spp,
        "seed": opts.seed,
        "denoise": opts.denoise,
        "max_bounces": MAX_DEPTH - 2,
        "threads": opts.threads,
        "material": material,
        "output": str(workdir / "blender.npy"),
    }
    job_path = workdir / "job.json"
    job_path.write_text(json.dumps(job, indent=1), encoding="utf-8")
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "kesbrdf.export.blender_look", str(job_path)], env=env,
                              capture_output=True, text=True, timeout=BLENDER_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise ExportError(f"Blender render: expected to finish within {BLENDER_TIMEOUT_S} s, it did not "
                          f"(job {job_path})") from None
    if proc.returncode != 0 or not Path(job["output"]).is_file():
        tail = [ln for ln in (proc.stderr or "").splitlines() if ln.strip()][-1:] or ["no output"]
        raise ExportError(f"Blender render failed (exit {proc.returncode}): {tail[0]}")
    info = json.loads(Path(job["output"]).with_suffix(".info.json").read_text(encoding="utf-8"))
    info["seconds"] = round(time.perf_counter() - t0, 2)
    return np.load(job["output"]), info


def read_openpbr(path) -> dict:
    """The ``open_pbr_surface`` inputs of a kesbrdf ``.mtlx`` (and the tangent rotation, degrees)."""
    import MaterialX as mx

    doc = mx.createDocument()
    try:
        mx.readFromXmlFile(doc, str(path))
    except Exception as exc:  # MaterialX raises its own exception types
        raise ExportError(f"{path}: expected a MaterialX document, got an unreadable file ({exc})") from None
    shader = next((n for n in doc.getNodes() if n.getCategory() == "open_pbr_surface"), None)
    if shader is None:
        raise ExportError(f"{path}: expected an open_pbr_surface node, found none")
    out = {}
    for inp in shader.getInputs():
        v = inp.getValue()
        if v is None:
            continue
        out[inp.getName()] = [float(a) for a in v] if hasattr(v, "__len__") else float(v)
    rot = next((n for n in doc.getNodes() if n.getCategory() == "rotate3d"), None)
    amount = rot.getInput("amount") if rot is not None else None
    out["tangent_rotation_deg"] = float(amount.getValue()) if amount is not None else 0.0
    return out


#: Blender's Principled anisotropy: aspect √(1 − 0.9 a), α_x = α/aspect, α_y = α·aspect.
BLENDER_ANISO_SCALE = 0.9


def diffuse_throughput_ratio(ior: float, tint: float, alpha: float) -> float:
    """∫(1 − E(μ; F0(η)))μ dμ / ∫(1 − E(μ; F0(η)·tint))μ dμ with F90 = 1 (see :func:`openpbr_to_principled`)."""
    from kesbrdf.export.microfacet import ggx_directional_albedo

    mu = (np.arange(64) + 0.5) / 64
    f0 = ((ior - 1) / (ior + 1)) ** 2
    e_open = ggx_directional_albedo(mu, alpha, np.asarray([f0]), np.asarray([1.0]))[..., 0]
    e_blend = ggx_directional_albedo(mu, alpha, np.asarray([f0 * min(max(tint, 0.0), 1.0)]), np.asarray([1.0]))[..., 0]
    return float(np.sum((1 - e_open) * mu) / np.sum((1 - e_blend) * mu))


def openpbr_to_principled(p: dict) -> dict:
    """Principled BSDF inputs (Blender 4.5) for OpenPBR Surface parameters.

    Mapping (the approximation is the difference of the two models):

    - base_color → Base Color × k; Lambert diffuse (Diffuse Roughness 0), Metallic 0.
      OpenPBR's diffuse sits under the *untinted* specular layer (throughput
      1 − E_spec(F0(η))), Blender's under its tinted one (1 − E_spec(F0(η)·c̄)): k is the
      ratio of the two throughputs averaged over the cosine-weighted hemisphere
      (MaterialX's GGX albedo fit, :func:`kesbrdf.export.microfacet.ggx_directional_albedo`),
      so the body keeps OpenPBR's brightness (k = 1 for an untinted specular);
    - (α_t, α_b) of ``ND_open_pbr_anisotropy`` → Roughness = (α_t α_b)^{1/4} and
      Anisotropic a with Blender's aspect √(1 − 0.9 a) = √(α_b/α_t) (clipped to [0, 1]:
      Blender cannot stretch a lobe beyond α_t/α_b = 10);
    - the tangent rotation ρ (degrees) → Anisotropic Rotation ρ/360 (turns), tangent
      from the UV map (u = warp);
    - specular_ior → IOR, specular_color → Specular Tint (Blender tints the reflection
      at normal incidence, OpenPBR the whole Fresnel curve), Specular IOR Level 0.5;
    - fuzz_weight, fuzz_color, fuzz_roughness → Sheen Weight, Tint, Roughness (both are
      Zeltner et al.'s microfibre sheen layered by albedo scaling).
    """
    from kesbrdf.export.openpbr import openpbr_alphas

    a_t, a_b = openpbr_alphas(float(p.get("specular_roughness", 0.3)), float(p.get("specular_roughness_anisotropy", 0.0)))
    a_t, a_b = float(a_t), float(a_b)
    ratio = a_b / a_t if a_t > 0 else 1.0
    aniso = float(np.clip((1.0 - ratio) / BLENDER_ANISO_SCALE, 0.0, 1.0))
    col = lambda k, d: list(p.get(k, d))[:3]  # noqa: E731
    k = diffuse_throughput_ratio(float(p.get("specular_ior", 1.5)), float(np.mean(col("specular_color", [1.0] * 3))),
                                 math.sqrt(a_t * a_b))
    return {
        "Base Color": [float(min(c * k, 1.0)) for c in col("base_color", [0.8] * 3)],
        "Metallic": 0.0,
        "Diffuse Roughness": 0.0,
        "Roughness": float((a_t * a_b) ** 0.25),
        "Anisotropic": aniso,
        "Anisotropic Rotation": float(p.get("tangent_rotation_deg", 0.0)) / 360.0 % 1.0,
        "IOR": float(p.get("specular_ior", 1.5)),
        "Specular IOR Level": 0.5,
        "Specular Tint": col("specular_color", [1.0] * 3),
        "Sheen Weight": float(p.get("fuzz_weight", 0.0)),
        "Sheen Tint": col("fuzz_color", [1.0] * 3),
        "Sheen Roughness": float(p.get("fuzz_roughness", 0.5)),
        "Coat Weight": 0.0,
    }


def render_export(fmt: str, path, scene: dict, opts: LookOptions, workdir) -> tuple[np.ndarray, dict]:
    """Render the exported file ``path`` of format ``fmt`` in its renderer (:data:`RENDERERS`)."""
    path = Path(path)
    if fmt not in RENDERERS:
        raise ExportError(f"look: expected a format with a renderer here ({', '.join(RENDERERS)}), got {fmt!r}")
    if not path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    if fmt == "rgl-bsdf":
        bsdf = {"type": "twosided", "bsdf": {"type": "measured", "filename": str(path)}}
        t0 = time.perf_counter()
        img, _ = _render_mitsuba(scene, bsdf, opts, opts.seed + 1)
        return img, {"seconds": round(time.perf_counter() - t0, 2)}
    if fmt == "gltf-threejs":
        return threejs_render(scene, path, opts, workdir)
    if fmt in ("gltf", "glb"):
        return blender_render(scene, {"source": "gltf", "path": str(path.resolve())}, opts, workdir)
    if fmt == "usd":
        return blender_render(scene, {"source": "usd", "path": str(path.resolve())}, opts, workdir)
    inputs = openpbr_to_principled(read_openpbr(path))
    return blender_render(scene, {"source": "principled", "inputs": inputs, "uv_tangent": True}, opts, workdir)


# -- three.js -------------------------------------------------------------------------------
#: The viewer's folder (its npm packages hold three.js and playwright-core).
VIEWER = Path(__file__).resolve().parents[3] / "viewer"
#: Point lights per side of each soft box in three.js (n² per box): three.js's
#: RectAreaLight shades with an isotropic LTC lobe and no sheen, so the soft boxes become
#: grids of point lights, which shade with the full MeshPhysicalMaterial.
THREEJS_GRID = 4
#: Samples per pixel side in three.js (box-filtered down: the plugin's one-pixel box filter).
THREEJS_SUPERSAMPLE = 3
#: Seconds the three.js render may take (node + Chromium start, shader compile, render).
THREEJS_TIMEOUT_S = 180
#: The row's reason when three.js cannot run here.
THREEJS_MISSING = "needs chromium and viewer/node_modules (node, `make viewer`)"


def _chromium() -> str | None:
    return shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)


def _require_threejs() -> None:
    mods = VIEWER / "node_modules"
    if (shutil.which("node") is None or _chromium() is None or not (mods / "three").is_dir()
            or not (mods / "playwright-core").is_dir()):
        raise RendererMissing(THREEJS_MISSING)


def threejs_lights(scene: dict, grid: int = THREEJS_GRID) -> list[dict]:
    """The soft boxes as ``grid``² point lights each (three.js ``PointLight``, decay 2).

    A patch of area A of a quad of radiance L, seen from the scene centre at angle θ_e to
    the quad's normal, sends intensity I = L A cos θ_e towards it; three.js's point light
    gives irradiance I cos θ_i / d² (no π: three.js lights are in photometric-style units
    with radiometric meaning since r155).  Exact for the lights' far field; near a box
    the patches resolve it to 1/``grid`` of its size."""
    c0 = np.asarray(scene["center"], float)
    out = []
    for corners, radiance in scene["lights"]:
        q = np.asarray(corners, float)
        ex, ey = q[1] - q[0], q[3] - q[0]
        normal = np.cross(ex, ey)
        area = float(np.linalg.norm(normal))
        normal /= area
        rad = np.asarray(radiance, float)
        peak = float(rad.max())
        for i in range(grid):
            for j in range(grid):
                pos = q[0] + (i + 0.5) / grid * ex + (j + 0.5) / grid * ey
                to_c = c0 - pos
                cos_e = max(float(np.dot(normal, to_c / np.linalg.norm(to_c))), 0.0)
                out.append({"position": pos.tolist(), "color": (rad / peak).tolist(),
                            "intensity": peak * area / grid**2 * cos_e})
    return out


def _uv_tangents(p, n, uv, f) -> np.ndarray:
    """Per-vertex unit ∂p/∂u ⟂ n, w = +1 (the convention of the export's own preview meshes)."""
    P, U = p[f], uv[f]
    dp1, dp2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    du1, dv1 = U[:, 1, 0] - U[:, 0, 0], U[:, 1, 1] - U[:, 0, 1]
    du2, dv2 = U[:, 2, 0] - U[:, 0, 0], U[:, 2, 1] - U[:, 0, 1]
    det = du1 * dv2 - du2 * dv1
    t_face = (dp1 * dv2[:, None] - dp2 * dv1[:, None]) * np.sign(det)[:, None]
    t = np.zeros_like(p, dtype=float)
    for k in range(3):
        np.add.at(t, f[:, k], t_face)
    t -= np.sum(t * n, -1, keepdims=True) * n
    length = np.linalg.norm(t, axis=-1, keepdims=True)
    fallback = np.cross(n, [0.0, 0.0, 1.0])  # the sphere's poles: no ∂p/∂u there
    t = np.where(length > 1e-12, t / np.maximum(length, 1e-12), fallback)
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)
    return np.concatenate([t, np.ones((len(t), 1))], -1)


def threejs_render(scene: dict, path, opts: LookOptions, workdir) -> tuple[np.ndarray, dict]:
    """Render ``scene`` in three.js with the material GLTFLoader makes of the glTF/glb ``path``
    (``viewer/scripts/gltf-look.mjs``); returns (linear image, info).

    Same camera, meshes (positions, normals, UVs, tangents ∂p/∂u) and floor albedo as the
    plugin render; the soft boxes become :func:`threejs_lights`; WebGL rasterises direct
    light only (no shadows, no floor bounce: the approximation, docs/exports.md)."""
    _require_threejs()
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    objects = []
    for name, (p, n, uv, f) in scene["objects"].items():
        o = {"name": name, "fabric": name in scene["fabric"], "position": np.asarray(p, float).ravel().tolist(),
             "normal": np.asarray(n, float).ravel().tolist(), "uv": np.asarray(uv, float).ravel().tolist(),
             "index": np.asarray(f, int).ravel().tolist()}
        if o["fabric"]:
            o["tangent"] = _uv_tangents(np.asarray(p, float), np.asarray(n, float), np.asarray(uv, float),
                                        np.asarray(f, int)).ravel().tolist()
        objects.append(o)
    lights = threejs_lights(scene)
    w, h = scene["resolution"]
    job = {"gltf": str(Path(path).resolve()), "objects": objects, "floor_albedo": scene["floor_albedo"],
           "lights": lights, "camera": scene["camera"], "width": int(w), "height": int(h),
           "supersample": THREEJS_SUPERSAMPLE, "output": str(workdir / "three.f32"),
           "info": str(workdir / "three.json")}
    job_path = workdir / "three-job.json"
    job_path.write_text(json.dumps(job), encoding="utf-8")
    env = dict(os.environ, CHROMIUM=_chromium())
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([shutil.which("node"), str(VIEWER / "scripts" / "gltf-look.mjs"), str(job_path)],
                              cwd=VIEWER, env=env, capture_output=True, text=True, timeout=THREEJS_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise ExportError(f"three.js render: expected to finish within {THREEJS_TIMEOUT_S} s, it did not "
                          f"(job {job_path})") from None
    if proc.returncode != 0 or not Path(job["output"]).is_file():
        tail = [ln for ln in (proc.stderr or "").splitlines() if ln.strip()][-1:] or ["no output"]
        raise ExportError(f"three.js render failed (exit {proc.returncode}): {tail[0]}")
    img = np.fromfile(job["output"], dtype="<f4").reshape(int(h), int(w), 3)
    info = json.loads(Path(job["info"]).read_text(encoding="utf-8"))
    info["point_lights"] = len(lights)
    info["seconds"] = round(time.perf_counter() - t0, 2)
    return img, info


# -- comparison ------------------------------------------------------------------------------
def _save_png(path: Path, img8: np.ndarray) -> Path:
    from PIL import Image

    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(img8)).save(tmp, format="PNG")
    return path


def write_side_by_side(path, left8, right8, titles, footer: str, flip8=None) -> Path:
    """Plugin render | export render (| FLIP map), labelled, as one PNG (atomically)."""
    from PIL import Image, ImageDraw

    imgs = [left8, right8] + ([flip8] if flip8 is not None else [])
    h, w = left8.shape[:2]
    band = 14
    panel = Image.new("RGB", (len(imgs) * w, h + 2 * band), (16, 16, 16))
    draw = ImageDraw.Draw(panel)
    for k, (img, title) in enumerate(zip(imgs, list(titles) + ["FLIP error"])):
        panel.paste(Image.fromarray(np.ascontiguousarray(img[..., :3])), (k * w, band))
        draw.text((k * w + 3, 1), title, fill=(230, 230, 230))
    draw.text((3, h + band + 1), footer, fill=(230, 230, 230))
    with atomic_path(Path(path)) as tmp:
        panel.save(tmp, format="PNG")
    return Path(path)


class PluginReference:
    """The plugin renders (two seeds), the fabric mask and the display exposure, made once."""

    def __init__(self, model_path, scene, opts):
        from kesbrdf.render.compare import auto_exposure, compare_images

        t0 = time.perf_counter()
        self.image, self.mask = render_plugin(model_path, scene, opts, opts.seed, want_mask=True)
        second, _ = render_plugin(model_path, scene, opts, opts.seed + 1)
        #: the second seed's render (the noise floor on any other mask)
        self.second = second
        self.seconds = round(time.perf_counter() - t0, 2)
        self.exposure = auto_exposure(self.image, self.mask)
        noise = compare_images(self.image, second, self.mask, self.exposure)
        self.noise = {"flip": noise["flip"], "rel_rmse": noise["rel_rmse"]}
        self.ref8 = noise["_ref8"]


def turned_warp_scene(scene: dict) -> dict:
    """``scene`` with the fabric's warp turned by 90° in the surface: UVs (u, v) → (1 − v, u),
    so ∂p/∂u' = −∂p/∂v (the weft) and the shading tangent the plugin builds from the UVs
    follows the old weft; geometry, lights and camera unchanged."""
    objects = dict(scene["objects"])
    for name in scene["fabric"]:
        p, n, uv, f = objects[name]
        objects[name] = (p, n, np.stack([1.0 - uv[:, 1], uv[:, 0]], -1), f)
    return {**scene, "objects": objects}


#: Per-pixel FLIP (:func:`kesbrdf.render.compare.flip_mean`'s map) between the plugin
#: render and the plugin render with the warp turned by 90° above which a fabric pixel
#: counts as showing the anisotropy direction (:func:`direction_mask`).  Above the
#: seed-to-seed noise: on the tests' Ward fabric (128 × 96, 32 spp + OIDN) the 99th
#: percentile of the FLIP map between two plugin seeds is 0.20.
DIRECTION_FLIP = 0.3


def direction_mask(model_path, ref: PluginReference, scene: dict, opts: LookOptions,
                   threshold: float = DIRECTION_FLIP) -> np.ndarray:
    """(H, W) bool: the fabric pixels of ``ref`` whose plugin render changes by more than
    FLIP ``threshold`` when the warp is turned by 90° (:func:`turned_warp_scene`).

    These are the pixels where a renderer's anisotropy direction is visible at all (the
    highlights' streaks); over the whole frame, diffuse areas and fit error dominate.  The
    mask comes from the plugin alone (two of its renders), never from the export's image.
    """
    from kesbrdf.render.compare import flip_mean
    from kesbrdf.render.scenes import to_srgb8

    turned, _ = render_plugin(model_path, turned_warp_scene(scene), opts, opts.seed)
    _, value, _ = flip_mean(to_srgb8(turned, ref.exposure), ref.ref8, ref.mask)
    return ref.mask & (value > threshold)


def compare_export(ref: PluginReference, fmt: str, path, scene: dict, opts: LookOptions, workdir,
                   mask: np.ndarray | None = None) -> dict:
    """Render one export in its renderer and compare it with the plugin render ``ref``
    (:func:`kesbrdf.render.compare.compare_images`: ``flip``, ``rel_rmse``, 8-bit images, FLIP map)
    plus ``_image`` (linear) and ``_info`` (renderer details).  ``mask`` (default the
    fabric, ``ref.mask``) selects the pixels the numbers are taken over."""
    from kesbrdf.render.compare import compare_images

    img, info = render_export(fmt, path, scene, opts, workdir)
    r = compare_images(ref.image, img, ref.mask if mask is None else mask, ref.exposure)
    r["_image"], r["_info"] = img, info
    return r


def _look_row(fmt, path, ref: PluginReference, scene, opts, out_dir: Path, workdir: Path) -> dict:
    r = compare_export(ref, fmt, path, scene, opts, workdir / fmt)
    info = r["_info"]
    stem = out_dir / f"look_{fmt}"
    _save_png(stem.with_name(stem.name + "_render.png"), r["_test8"])
    renderer = RENDERERS[fmt]
    footer = (f"{fmt} in {renderer}: FLIP {r['flip']:.3f}, relRMSE {r['rel_rmse']:.3f}   "
              f"noise floor: FLIP {ref.noise['flip']:.3f}, relRMSE {ref.noise['rel_rmse']:.3f}")
    side = write_side_by_side(stem.with_name(stem.name + "_side_by_side.png"), ref.ref8, r["_test8"],
                              ("kesbrdf plugin (Mitsuba 3)", f"{fmt}: {renderer}"), footer, r["_magma"])
    row = {
        "format": fmt,
        "file": str(path),
        "renderer": renderer,
        "flip": round(float(r["flip"]), 4),
        "rel_rmse": round(float(r["rel_rmse"]), 4),
        "noise_flip": round(float(ref.noise["flip"]), 4),
        "noise_rel_rmse": round(float(ref.noise["rel_rmse"]), 4),
        "images": {"plugin": str(out_dir / "look_plugin.png"),
                   "export": str(stem.with_name(stem.name + "_render.png")), "side_by_side": str(side)},
        "seconds": info.get("seconds"),
    }
    if "three" in info:
        row["three"] = {"revision": info["three"], "material": info.get("material", {}),
                        "point_lights": info.get("point_lights")}
    if "blender" in info:
        row["blender"] = info["blender"]
        row["principled"] = info.get("principled", {})
    return row


def check_looks(model_path, exports: dict, out_dir, opts: LookOptions | None = None, progress=None) -> dict:
    """Render every ``{format: file}`` of ``exports`` in its renderer and compare with the plugin.

    Writes ``look_plugin.png``, ``look_<fmt>_render.png`` and
    ``look_<fmt>_side_by_side.png`` into ``out_dir``.  A format whose renderer is missing
    (no ``bpy``) gets a row with ``skipped`` and the reason instead of numbers.

    Returns
    -------
    dict
        ``rows`` (one per format: renderer, flip, rel_rmse, noise_flip, noise_rel_rmse,
        images, seconds), ``scene``, ``options``, ``exposure``, ``plugin_seconds``.
    """
    opts = opts or LookOptions()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    unknown = [f for f in exports if f not in RENDERERS]
    if unknown:
        raise ExportError(f"look: expected formats from {', '.join(RENDERERS)}, got {', '.join(unknown)}")
    scene = studio_scene(opts.resolution)
    ref = PluginReference(model_path, scene, opts)
    _save_png(out_dir / "look_plugin.png", ref.ref8)
    rows = []
    with tempfile.TemporaryDirectory(prefix="kesbrdf-look-") as tmp:
        for fmt, path in exports.items():
            try:
                row = _look_row(fmt, path, ref, scene, opts, out_dir, Path(tmp))
            except RendererMissing as exc:
                row = {"format": fmt, "file": str(path), "renderer": RENDERERS[fmt], "skipped": str(exc)}
            if progress:
                progress(look_line(row))
            rows.append(row)
    return {
        "rows": rows,
        "model": str(model_path),
        "scene": "sphere + folded cloth, four studio soft boxes, no environment (kesbrdf.export.looks)",
        "reference": "kesbrdf Mitsuba plugin",
        "options": opts.to_json(),
        "exposure": ref.exposure,
        "fabric_pixels": int(ref.mask.sum()),
        "plugin_seconds": ref.seconds,
    }


def look_line(row: dict) -> str:
    """One readable line of a look row: 'gltf in Blender Cycles (...): FLIP 0.12, ...'."""
    if "skipped" in row:
        return f"{row['format']}: skipped ({row['skipped']})"
    return (f"{row['format']} in {row['renderer']}: FLIP {row['flip']:.3f}, relative RMSE {row['rel_rmse']:.3f} "
            f"against the measured model (noise floor {row['noise_flip']:.3f}, {row['noise_rel_rmse']:.3f})")


def check_look(model, fmt: str, path, out_dir=None, opts: LookOptions | None = None) -> dict:
    """One export's look (``kesbrdf export ... --check-look``); ``model`` a model file or model.

    Writes the images next to ``path`` (or into ``out_dir``) and ``<file>.look.json``.
    """
    path = Path(path)
    out_dir = Path(out_dir) if out_dir is not None else path.parent
    with tempfile.TemporaryDirectory(prefix="kesbrdf-look-model-") as tmp:
        model_path = Path(model) if isinstance(model, (str, os.PathLike)) else Path(tmp) / "model.kes.json"
        if not isinstance(model, (str, os.PathLike)):
            model.save(model_path)
        result = check_looks(model_path, {fmt: path}, out_dir, opts)
    write_text(path.with_name(path.name + ".look.json"), json.dumps(result, indent=1, default=str) + "\n")
    return result
