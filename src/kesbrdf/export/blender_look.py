"""The Blender side of :mod:`kesbrdf.export.looks`: one Cycles render of an exported material.

Run in its own process (``python -m kesbrdf.export.blender_look JOB.json``), because
``bpy`` (Blender as a Python module, the ``blender`` extra) bundles its own USD, OIDN,
TBB and LLVM, which must not meet Mitsuba's and usd-core's in one process.  The job
file (written by :func:`kesbrdf.export.looks.blender_render`) holds everything in the
renderer-neutral y-up world of :mod:`kesbrdf.render.scenes`:

``meshes``   an ``.npz`` with ``<name>_positions/_normals/_uvs/_faces`` per object, and
             ``objects``: [{"name", "material": "fabric" | "floor"}];
``lights``   rectangles as four corners (counter-clockwise seen from the lit side) and an
             RGB radiance (W sr⁻¹ m⁻²);
``camera``   origin, target, vertical field of view (degrees);
``material`` how the fabric's material reaches Blender:

- ``{"source": "gltf", "path"}``: Blender's own glTF importer
  (``bpy.ops.import_scene.gltf``); the material it builds is put on the scene's fabric
  objects and the imported preview meshes are deleted;
- ``{"source": "usd", "path"}``: Blender's USD importer (``bpy.ops.wm.usd_import``), the
  same way;
- ``{"source": "principled", "inputs": {socket: value}, "uv_tangent": bool}``: a
  Principled BSDF with these inputs (how a MaterialX/OpenPBR file is brought in, since
  Blender 4.5 reads no ``.mtlx``); ``uv_tangent`` feeds it the UV map's tangent.

World mapping: y-up (x, y, z) → Blender z-up (x, −z, y), a rotation, so every object,
light and the camera keep their relative placement and the image is the same.
Lights are emissive one-sided quads, not Blender lamps: an Emission shader of strength
1 has radiance equal to its colour, exactly Mitsuba's ``area`` emitter, and the back
(and the quad itself, for other lights) is a 0.5 grey diffuse like Mitsuba's default
BSDF.  The render writes a linear float32 ``.npy`` (H, W, 3), row 0 at the top.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np


def _to_blender(p):
    p = np.asarray(p, float)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def _reset(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _mesh_object(bpy, name, positions, normals, uvs, faces, material):
    mesh = bpy.data.meshes.new(name)
    pos = _to_blender(positions)
    mesh.from_pydata(pos.tolist(), [], np.asarray(faces, int).tolist())
    mesh.update()
    uv_layer = mesh.uv_layers.new(name="UVMap")  # the glTF importer's name for TEXCOORD_0
    loops = np.empty(len(mesh.loops), int)
    mesh.loops.foreach_get("vertex_index", loops)
    uv_layer.data.foreach_set("uv", np.asarray(uvs, np.float32)[loops].ravel())
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), bool))
    mesh.normals_split_custom_set_from_vertices(_to_blender(normals).tolist())
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _diffuse(bpy, name, rgb):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (*rgb, 1.0)
    d.inputs["Roughness"].default_value = 0.0  # Lambert
    nt.links.new(d.outputs[0], out.inputs["Surface"])
    return mat


def _emitter(bpy, name, radiance):
    """One-sided emission (front = the quad's normal), 0.5 grey diffuse everywhere (Mitsuba's default)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*radiance, 1.0)
    em.inputs["Strength"].default_value = 1.0
    dif = nt.nodes.new("ShaderNodeBsdfDiffuse")
    dif.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    dif.inputs["Roughness"].default_value = 0.0
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(em.outputs[0], add.inputs[0])
    nt.links.new(dif.outputs[0], add.inputs[1])
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs[0])
    nt.links.new(add.outputs[0], mix.inputs[1])
    nt.links.new(dif.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    return mat


def _imported_material(bpy, op, path):
    """Run an importer, keep the first material of the meshes it made, delete the objects."""
    before = set(bpy.data.objects)
    op(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before]
    mats = [s.material for o in new if o.type == "MESH" for s in o.material_slots if s.material is not None]
    if not mats:
        raise RuntimeError(f"{path}: the importer made no mesh with a material")
    for o in new:
        bpy.data.objects.remove(o, do_unlink=True)
    return mats[0]


def _principled(bpy, inputs: dict, uv_tangent: bool):
    mat = bpy.data.materials.new("kesbrdf_principled")
    mat.use_nodes = True
    nt = mat.node_tree
    node = nt.nodes["Principled BSDF"]
    for key, value in inputs.items():
        sock = node.inputs[key]
        if isinstance(value, (list, tuple)):
            value = list(value) + [1.0] * (len(sock.default_value) - len(value))
        sock.default_value = value
    if uv_tangent:
        t = nt.nodes.new("ShaderNodeTangent")
        t.direction_type = "UV_MAP"
        t.uv_map = "UVMap"
        nt.links.new(t.outputs["Tangent"], node.inputs["Tangent"])
    return mat


def _describe(material) -> dict:
    """The Principled BSDF inputs Blender ended up with (what the importer made of the file)."""
    out = {}
    if material.node_tree is None:
        return out
    for node in material.node_tree.nodes:
        if node.type != "BSDF_PRINCIPLED":
            continue
        for sock in node.inputs:
            if sock.type in ("VALUE", "RGBA") and sock.enabled:
                v = sock.default_value
                val = [round(float(a), 6) for a in v][:3] if sock.type == "RGBA" else round(float(v), 6)
                out[sock.name] = {"value": val, "linked": sock.is_linked}
        tangent = node.inputs.get("Tangent")
        src = tangent.links[0].from_node if tangent is not None and tangent.is_linked else None
        # unlinked, Cycles uses a radial tangent around the object's z axis, not the UVs
        out["Tangent"] = (f"{src.bl_idname}:{getattr(src, 'direction_type', '')}:{getattr(src, 'uv_map', '')}"
                          if src is not None else "default (radial about the object's z axis)")
        break
    return out


def render(job: dict) -> dict:
    """Build the scene of ``job`` in a fresh Blender, render with Cycles, save the ``.npy``."""
    import bpy
    from mathutils import Vector

    _reset(bpy)
    scene = bpy.context.scene
    src = job["material"]
    if src["source"] == "gltf":
        fabric = _imported_material(bpy, bpy.ops.import_scene.gltf, src["path"])
    elif src["source"] == "usd":
        fabric = _imported_material(bpy, bpy.ops.wm.usd_import, src["path"])
    elif src["source"] == "principled":
        fabric = _principled(bpy, src["inputs"], bool(src.get("uv_tangent", True)))
    else:
        raise ValueError(f"unknown material source {src['source']!r}")
    floor = _diffuse(bpy, "floor", job["floor_albedo"])
    data = np.load(job["meshes"])
    for obj in job["objects"]:
        n = obj["name"]
        _mesh_object(bpy, n, data[f"{n}_positions"], data[f"{n}_normals"], data[f"{n}_uvs"], data[f"{n}_faces"],
                     fabric if obj["material"] == "fabric" else floor)
    for k, light in enumerate(job["lights"]):
        corners = np.asarray(light["corners"], float)
        normals = np.repeat(np.cross(corners[1] - corners[0], corners[2] - corners[0])[None], 4, 0)
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
        _mesh_object(bpy, f"light_{k}", corners, normals, uvs, [[0, 1, 2], [0, 2, 3]],
                     _emitter(bpy, f"light_{k}", light["radiance"]))
    # camera
    cam = job["camera"]
    cdata = bpy.data.cameras.new("camera")
    cdata.sensor_fit = "VERTICAL"
    cdata.angle_y = math.radians(cam["fov_y_deg"])
    cdata.clip_start = 1e-3
    cdata.clip_end = 1e3
    cobj = bpy.data.objects.new("camera", cdata)
    scene.collection.objects.link(cobj)
    origin = Vector(_to_blender(cam["origin"]).tolist())
    target = Vector(_to_blender(cam["target"]).tolist())
    cobj.location = origin
    cobj.rotation_euler = (target - origin).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cobj
    # world: black (the studio is lit by the quads alone)
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    # Cycles: CPU, fixed samples, no clamping or glossy blur (an unbiased path tracer like Mitsuba's)
    w, h = job["resolution"]
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = int(w), int(h), 100
    r.threads_mode = "FIXED"
    r.threads = int(job.get("threads", 2))
    r.film_transparent = False
    c = scene.cycles
    c.device = "CPU"
    c.samples = int(job["spp"])
    c.seed = int(job.get("seed", 0))
    c.use_adaptive_sampling = False
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = int(job["max_bounces"])
    c.transmission_bounces = c.volume_bounces = c.transparent_max_bounces = int(job["max_bounces"])
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.light_sampling_threshold = 0.0
    c.filter_type = "BOX"
    c.filter_width = 1.0
    c.use_denoising = bool(job.get("denoise", True))
    if c.use_denoising:
        c.denoiser = "OPENIMAGEDENOISE"
        c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        c.denoising_prefilter = "ACCURATE"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    exr = Path(job["output"]).with_suffix(".exr")
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGB"
    r.filepath = str(exr)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(str(exr))
    px = np.empty(img.size[0] * img.size[1] * img.channels, np.float32)
    img.pixels.foreach_get(px)
    arr = px.reshape(img.size[1], img.size[0], img.channels)[::-1, :, :3]
    np.save(job["output"], np.ascontiguousarray(arr))
    exr.unlink(missing_ok=True)
    return {"blender": bpy.app.version_string, "principled": _describe(fabric), "material": fabric.name}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    job = json.loads(Path(argv[0]).read_text(encoding="utf-8"))
    info = render(job)
    Path(job["output"]).with_suffix(".info.json").write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
