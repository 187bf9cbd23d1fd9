"""Scenes for rendering a kesbrdf model, written as Mitsuba scene dicts (``mi.load_dict``).

Scenes (``SCENES``):

``sphere``
    A sphere with the fabric BSDF over a grey floor.  Mitsuba's sphere has u along
    the longitude (around its axis, here the world's up), so the warp runs around it.
``swatch``
    A flat square of fabric seen from above at an angle, u (warp) along world x.
    ``uv_rotation_deg=90`` turns the UVs so the warp runs along world z.
``drape``
    A drape folder from ``kesbrdf drape`` (one frame and its colliders); without a
    folder, a procedurally folded sheet over a dome (u = warp across the folds;
    ``uv_rotation_deg=90`` puts the warp along them).
``dressform``
    A dress form built from primitives (ellipsoid torso, neck, pole, base) wearing a
    garment: the drape folder's frame when given, else a procedural flared skirt.
``garment``
    A ``kesbrdf drape --scene garment`` folder: the gored skirt on the procedural
    mannequin (turned by the frame's ``body_rotation_deg``), on a studio floor, framed
    on the skirt and the torso, seen from the front.

Lighting needs no downloads (``ENVIRONMENTS``, ``LIGHTS``): a generated latitude–
longitude map (``sky``: gradient sky with a sun; ``studio``: dark room with two soft
boxes; ``uniform``: constant white, the furnace) and/or a rectangular area light or a
directional sun.  World space is y-up; drape folders written z-up (``"up_axis": "z"`` in
drape.json, or guessed from the direction the cloth falls) are rotated on load.
"""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf._drjit import load_dict as _load_dict
from kesbrdf.errors import FormatError, KesbrdfError, validate_choice, where
from kesbrdf.io.ply import read_ply, write_ply
from kesbrdf.render import mesh as _mesh

__all__ = [
    "SCENES",
    "ENVIRONMENTS",
    "LIGHTS",
    "RenderOptions",
    "Drape",
    "read_drape",
    "bsdf_dict",
    "load_scene",
    "render_scene",
    "to_srgb8",
    "save_image",
    "render_still",
]

SCENES = ("sphere", "swatch", "drape", "dressform", "garment")
ENVIRONMENTS = ("studio", "sky", "uniform", "none", "studio-hdr", "sunsky")
LIGHTS = ("area", "sun", "none", "studio")
#: Largest image accepted (pixels): 8K UHD.  Bigger requests are a typo, not a render.
MAX_PIXELS = 7680 * 4320
#: Floor under the studio soft boxes: dark grey, so the fabric, not the floor, carries the shot.
STUDIO_FLOOR_ALBEDO = (0.04, 0.04, 0.042)
#: Diffuse albedo of the mannequin (a warm ivory jersey cover).
MANNEQUIN_ALBEDO = (0.62, 0.58, 0.52)
#: Diffuse albedo of floors and dress forms.
PROP_ALBEDO = (0.42, 0.42, 0.42)
#: Loop subdivision levels of a sewn garment's render mesh (:mod:`kesbrdf.cloth.render_mesh`):
#: one level turns the 1–2 cm simulation cells of the showcase garment into 5–10 mm
#: triangles, 3–6 px at 720p in the garment shot (1.8 mm a pixel), with smooth normals.
GARMENT_SUBDIVISION_LEVELS = 1
#: Vertical field of view of the camera, degrees.
FOV_DEG = 32.0


@dataclass
class RenderOptions:
    """Everything that sets up a render besides the model and the scene name."""

    spp: int = 32
    resolution: tuple[int, int] = (320, 240)
    light: str = "area"
    env: str = "studio"
    base_color: tuple | None = None
    lobe_tint: tuple | None = None
    #: the KES mapping of the ``kesbrdf`` table plugin; None: the model's own
    #: (``default_mapping``: ``halfvector`` for new fits, ``deviation`` for older files)
    mapping: str | None = None
    two_sided: bool = True
    sampling: str = "lobe"
    max_depth: int = 4
    seed: int = 0
    uv_rotation_deg: float = 0.0
    exposure: float = 0.0
    floor: bool = True
    #: lobe beyond the last measured deviation (kesbrdf plugin ``extrapolation``):
    #: renders fade it (measured closer to the reference satins, docs/rendering.md);
    #: None leaves the model file's own setting
    extrapolation: str | None = "fade"
    tonemap: str = "clip"
    denoise: bool = False
    #: an 18 % grey card in the frame's lower left, facing the camera
    #: (:func:`grey_card_box`; the exposure reference of :mod:`kesbrdf.render.exposure`)
    grey_card: bool = False
    integrator: dict | None = field(default=None, repr=False)

    def validate(self) -> "RenderOptions":
        validate_choice("environment", self.env, ENVIRONMENTS)
        validate_choice("light", self.light, LIGHTS)
        from kesbrdf.render.post import CURVES

        validate_choice("tone curve", self.tonemap, CURVES)
        w, h = self.resolution
        if not (int(w) > 0 and int(h) > 0 and int(self.spp) > 0):
            raise KesbrdfError(f"expected positive resolution and spp, got {w}x{h} and {self.spp}")
        if int(w) * int(h) > MAX_PIXELS:
            raise KesbrdfError(f"resolution: expected at most {MAX_PIXELS} pixels, got {w}x{h}")
        if not 1 <= int(self.max_depth) <= 1024:
            raise KesbrdfError(f"max_depth: expected a path length in [1, 1024], got {self.max_depth}")
        if int(self.seed) < 0:
            raise KesbrdfError(f"seed: expected an integer >= 0, got {self.seed}")
        if not math.isfinite(float(self.exposure)):
            raise KesbrdfError(f"exposure: expected a finite number of stops, got {self.exposure}")
        return self

    def to_json(self) -> dict:
        d = asdict(self)
        d.pop("integrator")
        return d


# -- drape folders -------------------------------------------------------------------
@dataclass
class Drape:
    """A drape folder (``kesbrdf drape`` output)."""

    root: Path
    fps: float
    frames: list[Path]
    colliders: list[Path]
    scene: str
    up_axis: str
    body_rotation_deg: list | None = None
    moving: tuple = ()
    #: stitched vertex pairs of a sewn garment (drape.json ``cloth.seams``), else None
    seams: list | None = None
    _smooth: object = field(default=None, repr=False, compare=False)

    def smooth_mesh(self):
        """The welded, subdivided render mesh of a sewn garment (:mod:`kesbrdf.cloth.render_mesh`),
        built once from the first frame's faces and UVs; None for a drape without seams."""
        if self.seams is None:
            return None
        if self._smooth is None:
            from kesbrdf.cloth.render_mesh import SmoothMesh

            first = read_ply(self.frames[0])
            self._smooth = SmoothMesh(first.faces, first.uv, np.asarray(self.seams, np.int64),
                                      levels=GARMENT_SUBDIVISION_LEVELS)
        return self._smooth

    def cloth_mesh(self, index: int):
        """``(positions, normals, uv, faces)`` of frame ``index`` as rendered (drape coordinates)."""
        m = read_ply(self.frames[index])
        sm = self.smooth_mesh()
        if sm is None:
            return m.vertices, m.normals, m.uv, m.faces
        p, n = sm.apply(m.vertices)
        return p, n, sm.uv, sm.faces


def read_drape(path) -> Drape:
    """Read ``drape.json`` of a drape folder; errors name the file."""
    root = Path(path)
    meta_path = root / "drape.json"
    if not meta_path.is_file():
        raise FormatError(f"{where(root)}expected a drape folder with drape.json, got none")
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise FormatError(f"{where(meta_path, exc.lineno)}expected JSON, got {exc.msg}") from None
    frames = [root / str(f) for f in meta.get("frames", [])]
    if not frames:
        raise FormatError(f"{where(meta_path)}expected a non-empty 'frames' list, got {meta.get('frames')!r}")
    missing = [str(f) for f in frames if not f.is_file()]
    if missing:
        raise FormatError(f"{where(meta_path)}frame file(s) missing: {', '.join(missing[:3])}")
    colliders = []
    for c in meta.get("colliders", []):
        name = c.get("file") if isinstance(c, dict) else c
        colliders.append(root / str(name))
    up = str(meta.get("up_axis") or _guess_up_axis(frames[0], frames[-1])).lower()
    validate_choice("up_axis", up, ("y", "z"), meta_path, error=FormatError)
    moving = tuple(k for k, c in enumerate(meta.get("colliders", [])) if isinstance(c, dict) and c.get("moves"))
    rot = meta.get("body_rotation_deg")
    cloth = meta.get("cloth") if isinstance(meta.get("cloth"), dict) else {}
    seams = cloth.get("seams") if isinstance(cloth.get("seams"), list) and cloth.get("seams") else None
    return Drape(root, float(meta.get("fps", 24.0)), frames, colliders, str(meta.get("scene", "sphere")), up,
                 [float(a) for a in rot] if isinstance(rot, list) else None, moving, seams)


def _centroid(path) -> np.ndarray:
    shape = _load_dict({"type": "ply", "filename": str(path)})
    return np.array(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3).mean(axis=0)


def _guess_up_axis(first, last) -> str:
    """Up axis of a drape without ``up_axis``: the cloth falls, so its centroid moves
    down along it from the first to the last frame; newton's default ``z`` when unclear."""
    if first == last:
        return "z"
    move = _centroid(last) - _centroid(first)
    axis = int(np.argmin(move))
    if move[axis] < -2 * np.abs(np.delete(move, axis)).max() and axis in (1, 2):
        return "yz"[axis - 1]
    return "z"


# -- pieces of scene dicts ----------------------------------------------------------
def bsdf_dict(model_path, opts: RenderOptions, model=None) -> dict:
    """The BSDF entry for a model file and the colour options.

    The model says which plugin draws it and which options that plugin takes
    (``model.render_plugin``, :mod:`kesbrdf.models.base`): ``kesbrdf`` (the (φ, γ) table,
    with ``opts.mapping``) unless the kind has its own.  ``model`` saves reading the file
    again when the caller has it.
    """
    if model is None or isinstance(model, str):
        from kesbrdf.io.model_file import load_model

        model = load_model(Path(model_path))
    plugin, props = model.render_plugin(mapping=opts.mapping, extrapolation=opts.extrapolation)
    d = {
        "type": plugin,
        "filename": str(model_path),
        "two_sided": bool(opts.two_sided),
        "sampling": opts.sampling,
        **props,
    }
    if opts.base_color is not None:
        d["base_color"] = ",".join(f"{float(c):.6g}" for c in opts.base_color)
    if opts.lobe_tint is not None:
        d["lobe_tint"] = ",".join(f"{float(c):.6g}" for c in opts.lobe_tint)
    return d


def _diffuse(rgb=PROP_ALBEDO) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}


def environment_bitmap(kind: str, width: int = 256) -> np.ndarray:
    """Generated lat-long radiance map (H = width/2, W, 3), y-up, row 0 at the zenith."""
    h = width // 2
    theta = (np.arange(h) + 0.5) / h * math.pi  # from +y
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    # direction (Mitsuba's envmap: u = atan2(x, -z) / 2π, v = θ / π)
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    if kind == "uniform":
        return np.ones((h, width, 3), np.float32)
    if kind == "sky":
        elev = np.clip(d[..., 1], -1, 1)
        zenith = np.array([0.18, 0.32, 0.75])
        horizon = np.array([0.85, 0.85, 0.9])
        ground = np.array([0.12, 0.11, 0.1])
        t = np.clip(elev, 0, 1)[..., None] ** 0.5
        img = np.where(elev[..., None] > 0, horizon * (1 - t) + zenith * t, ground)
        sun = np.array([math.cos(math.radians(40)) * 0.6, math.sin(math.radians(40)), math.cos(math.radians(40)) * 0.8])
        cos_s = d @ (sun / np.linalg.norm(sun))
        img = img + np.array([30.0, 27.0, 22.0]) * np.exp((cos_s - 1) / 0.0015)[..., None]
        return img.astype(np.float32)
    # studio: dark room, a large overhead soft box and a strip at the side
    img = np.full((h, width, 3), 0.04)
    overhead = np.exp(-((d[..., 1] - 1) ** 2) / 0.02) * 2.5
    strip_dir = np.array([-0.8, 0.35, 0.5])
    strip_dir /= np.linalg.norm(strip_dir)
    strip = np.exp(-(((d[..., 1] - 0.35) / 0.35) ** 2)) * np.exp(-((d @ strip_dir - 1) ** 2) / 0.05) * 3.0
    img = img + (overhead + strip)[..., None] * np.array([1.0, 0.98, 0.95])
    return img.astype(np.float32)


def _lights(opts: RenderOptions, center, radius, key_dir=(0.45, 0.72, 0.6)) -> dict:
    out = {}
    if opts.env == "studio-hdr":
        from kesbrdf.render.studio import environment_map

        out["environment"] = {"type": "envmap", "bitmap": mi.Bitmap(environment_map())}
    elif opts.env == "sunsky":
        out["environment"] = {"type": "sunsky", "sun_direction": [-0.45, 0.75, 0.5]}
    elif opts.env != "none":
        out["environment"] = {"type": "envmap", "bitmap": mi.Bitmap(environment_bitmap(opts.env))}
    if opts.light == "area":
        c = np.asarray(center)
        key_dir = np.asarray(key_dir, float) / np.linalg.norm(key_dir)
        origin = c + 3.6 * radius * key_dir
        size = 0.6 * radius
        out["key_light"] = {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=c.tolist(), up=[0, 1, 0])
            @ mi.ScalarTransform4f().scale([size, size, 1.0]),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [9.0, 8.8, 8.4]}},
        }
    elif opts.light == "studio":
        from kesbrdf.render.studio import studio_lights

        out.update(studio_lights(mi, center, radius))
    elif opts.light == "sun":
        out["sun"] = {
            "type": "directional",
            "direction": [-0.45, -0.75, -0.5],
            "irradiance": {"type": "rgb", "value": [3.0, 2.9, 2.7]},
        }
    return out


def _camera(opts: RenderOptions, center, radius, direction=(0.0, 0.55, 1.0)) -> dict:
    w, h = (int(v) for v in opts.resolution)
    direction = np.asarray(direction, float)
    direction /= np.linalg.norm(direction)
    fov = FOV_DEG if w >= h else FOV_DEG * w / h
    dist = 0.95 * radius / math.sin(math.radians(fov) / 2)
    origin = np.asarray(center) + dist * direction
    return {
        "type": "perspective",
        "fov": fov,
        "fov_axis": "y" if w >= h else "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=list(map(float, center)), up=[0, 1, 0]),
        # OIDN needs uncorrelated per-pixel noise: a box filter when denoising (a Gaussian
        # spreads each sample over neighbouring pixels and the denoiser keeps that noise)
        "film": {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgb",
                 "rfilter": {"type": "box" if opts.denoise else "gaussian"}},
        "sampler": {"type": "independent", "sample_count": int(opts.spp), "seed": int(opts.seed)},
    }


def _ply_shape(path, bsdf: dict, up_axis: str = "y", turn_deg: float = 0.0) -> "mi.Shape":
    """A PLY file as a shape; z-up files are turned y-up, ``turn_deg`` about the up axis first."""
    d = {"type": "ply", "filename": str(path), "bsdf": bsdf}
    T = mi.ScalarTransform4f
    spin = T().rotate([0, 0, 1] if up_axis == "z" else [0, 1, 0], float(turn_deg))
    if up_axis == "z":
        d["to_world"] = T().rotate([1, 0, 0], -90) @ spin
    elif turn_deg:
        d["to_world"] = spin
    return _load_dict(d)


def _mesh_shape(workdir: Path, name: str, mesh, bsdf: dict) -> "mi.Shape":
    path = workdir / f"{name}.ply"
    positions, normals, uvs, faces = mesh
    write_ply(path, positions, faces, normals, uvs)
    return _ply_shape(path, bsdf)


def _bbox(shapes):
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for s in shapes:
        b = s.bbox()
        lo = np.minimum(lo, np.array(b.min, float).ravel())
        hi = np.maximum(hi, np.array(b.max, float).ravel())
    return lo, hi


def _dressform_props(workdir: Path) -> dict:
    """A dress form from primitives: ellipsoid torso, neck, pole and base (y-up)."""
    grey = _diffuse((0.55, 0.52, 0.48))
    dark = _diffuse((0.08, 0.08, 0.08))
    T = mi.ScalarTransform4f
    return {
        "torso": _mesh_shape(workdir, "torso", _mesh.ellipsoid((0, 1.2, 0), (0.17, 0.3, 0.12)), grey),
        "hips": _mesh_shape(workdir, "hips", _mesh.ellipsoid((0, 0.98, 0), (0.175, 0.1, 0.13)), grey),
        "neck": {
            "type": "cylinder", "p0": [0, 1.42, 0], "p1": [0, 1.56, 0], "radius": 0.045, "bsdf": grey,
        },
        "pole": {"type": "cylinder", "p0": [0, 0.02, 0], "p1": [0, 0.95, 0], "radius": 0.015, "bsdf": dark},
        "base": {"type": "disk", "to_world": T().translate([0, 0.02, 0]) @ T().rotate([1, 0, 0], -90) @ T().scale(0.22), "bsdf": dark},
    }


#: Grey card: albedo, where its centre projects (normalised device coordinates, x right,
#: y up, in [−1, 1]), its side as a fraction of the smaller half-extent of the view at
#: its depth, and how far in front of the subject's centre it stands (units of r).
GREY_CARD_ALBEDO = 0.18
GREY_CARD_NDC = (-0.74, -0.6)
GREY_CARD_SIZE = 0.3
GREY_CARD_FORWARD = 0.8


def _view(opts: RenderOptions, center, radius, direction):
    """Camera origin, fov (degrees, about the longer axis' rule of :func:`_camera`), and
    the unit forward, right and up vectors."""
    w, h = (int(v) for v in opts.resolution)
    direction = np.asarray(direction, float)
    direction /= np.linalg.norm(direction)
    fov = FOV_DEG if w >= h else FOV_DEG * w / h
    dist = 0.95 * radius / math.sin(math.radians(fov) / 2)
    origin = np.asarray(center, float) + dist * direction
    fwd = -direction
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return origin, dist, fov, fwd, right, up


def _grey_card_geometry(opts: RenderOptions, center, radius, direction):
    """(centre, half side, camera origin, camera up) of the grey card of :func:`_grey_card`."""
    w, h = (int(v) for v in opts.resolution)
    origin, dist, fov, fwd, right, up = _view(opts, center, radius, direction)
    depth = dist - GREY_CARD_FORWARD * radius
    t = math.tan(math.radians(fov) / 2) * depth
    hw, hh = (t * w / h, t) if w >= h else (t, t * h / w)
    c = origin + depth * fwd + GREY_CARD_NDC[0] * hw * right + GREY_CARD_NDC[1] * hh * up
    return c, 0.5 * GREY_CARD_SIZE * min(hw, hh), origin, up


def _grey_card(opts: RenderOptions, center, radius, direction) -> dict:
    """A square 18 % Lambertian card facing the camera, at :data:`GREY_CARD_NDC`."""
    c, half, origin, up = _grey_card_geometry(opts, center, radius, direction)
    T = mi.ScalarTransform4f
    return {"type": "rectangle",
            "to_world": T().look_at(origin=c.tolist(), target=origin.tolist(), up=up.tolist()) @ T().scale([half, half, 1.0]),
            "bsdf": _diffuse((GREY_CARD_ALBEDO,) * 3)}


#: The exposure meter's view: the card's inner METER_FILL of its side fills the frame.
METER_FILL = 0.7


def _meter_camera(opts: RenderOptions, center, radius, direction, size: int, spp: int) -> dict:
    """A camera at the still's viewpoint aimed at the grey card, the card filling its
    ``size`` × ``size`` frame (the meter of :func:`kesbrdf.render.exposure.meter_exposure`)."""
    c, half, origin, up = _grey_card_geometry(opts, center, radius, direction)
    fov = 2 * math.degrees(math.atan(METER_FILL * half / float(np.linalg.norm(c - origin))))
    return {"type": "perspective", "fov": fov,
            "to_world": mi.ScalarTransform4f().look_at(origin=origin.tolist(), target=c.tolist(), up=up.tolist()),
            "film": {"type": "hdrfilm", "width": size, "height": size, "pixel_format": "rgb", "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": int(spp), "seed": 0}}


def grey_card_box(resolution, margin: float = 0.25) -> tuple[slice, slice]:
    """(rows, columns) of the grey card's pixels in an image of ``resolution`` (w, h),
    shrunk by ``margin`` of its side on each edge (antialiased edges left out)."""
    w, h = (int(v) for v in resolution)
    cx = (0.5 + 0.5 * GREY_CARD_NDC[0]) * w
    cy = (0.5 - 0.5 * GREY_CARD_NDC[1]) * h
    half = 0.5 * GREY_CARD_SIZE * 0.5 * min(w, h) * (1 - 2 * margin)
    half = max(half, 0.5)
    return slice(int(round(cy - half)), int(round(cy + half)) or 1), slice(int(round(cx - half)), int(round(cx + half)) or 1)


def load_scene(model_path, scene: str, opts: RenderOptions, drape=None, frame: int | None = None,
               cloth_bsdf: dict | None = None, framing=None, subject: bool = True,
               meter: tuple[int, int] | None = None) -> "mi.Scene":
    """Build and load one scene.

    Parameters
    ----------
    model_path : path
        Model file for the fabric BSDF (ignored when ``cloth_bsdf`` is given).
    scene : {"sphere", "swatch", "drape", "dressform"}
    opts : RenderOptions
    drape : Drape or path, optional
        Drape folder for ``drape``/``dressform``; its frame ``frame`` (default: last).
    cloth_bsdf : dict, optional
        Replace the fabric BSDF (benchmarks compare with Mitsuba's own BSDFs).
    framing : (center, radius), optional
        Fix the camera (animations keep one framing for every frame).
    subject : bool
        False leaves out the cloth and its props (mannequin, dress form) but keeps the
        framing, floor, backdrop, lights and grey card: the exposure meter's scene
        (:func:`kesbrdf.render.exposure.meter_exposure`).
    meter : (size, spp), optional
        Replace the camera by the exposure meter's: aimed at the grey card from the
        still's viewpoint, the card filling a size × size frame (:func:`_meter_camera`).
    """
    validate_choice("scene", scene, SCENES)
    opts.validate()
    if cloth_bsdf is None:
        from kesbrdf.render.bsdf import check_model

        cloth_bsdf = bsdf_dict(model_path, opts, check_model(model_path, opts.mapping))
    bsdf = cloth_bsdf
    if isinstance(drape, (str, Path)):
        drape = read_drape(drape)
    shapes: dict = {}
    extra: dict = {}
    floor = True
    view_dir = (0.0, 0.55, 1.0)
    key_dir = (0.45, 0.72, 0.6)
    with tempfile.TemporaryDirectory(prefix="kesbrdf-render-") as tmp:
        workdir = Path(tmp)
        if scene == "sphere":
            T = mi.ScalarTransform4f
            shapes["cloth"] = _load_dict({
                "type": "sphere",
                "to_world": T().translate([0, 1, 0]) @ T().rotate([1, 0, 0], -90),
                "bsdf": bsdf,
            })
        elif scene == "swatch":
            p, n, uv, f = _mesh.swatch(size=1.0)
            shapes["cloth"] = _mesh_shape(workdir, "swatch", (p, n, _mesh.rotate_uv(uv, opts.uv_rotation_deg), f), bsdf)
            floor = False
            view_dir = (0.0, 1.0, 0.75)
            key_dir = (0.0, 1.0, -0.75)  # mirror of the camera: the highlight sits mid-swatch
        elif drape is not None:
            index = len(drape.frames) - 1 if frame is None else int(frame)
            if not 0 <= index < len(drape.frames):
                raise KesbrdfError(f"{where(drape.root)}expected a frame index in [0, {len(drape.frames) - 1}], got {frame}")
            if drape.seams is not None:  # a sewn garment: welded, subdivided, smooth (cloth.render_mesh)
                path = workdir / "cloth.ply"
                p, n, uv, f = drape.cloth_mesh(index)
                write_ply(path, p, f, n, uv)
                shapes["cloth"] = _ply_shape(path, bsdf, drape.up_axis)
            else:
                shapes["cloth"] = _ply_shape(drape.frames[index], bsdf, drape.up_axis)
            turn = drape.body_rotation_deg[index] if drape.body_rotation_deg and index < len(drape.body_rotation_deg) else 0.0
            prop = _diffuse(MANNEQUIN_ALBEDO) if scene == "garment" else _diffuse((0.5, 0.48, 0.45))
            for k, c in enumerate(drape.colliders):
                if c.is_file():
                    shapes[f"collider_{k}"] = _ply_shape(c, prop if k in drape.moving else _diffuse((0.5, 0.48, 0.45)),
                                                         drape.up_axis, turn if k in drape.moving else 0.0)
        elif scene == "garment":
            raise KesbrdfError("scene 'garment' needs a drape folder from `kesbrdf drape --scene garment`")
        elif scene == "drape":
            p, n, uv, f = _mesh.folded_cloth()
            shapes["cloth"] = _mesh_shape(workdir, "folded", (p, n, _mesh.rotate_uv(uv, opts.uv_rotation_deg), f), bsdf)
        else:  # dressform with a procedural skirt
            shapes["cloth"] = _mesh_shape(workdir, "skirt", _mesh.skirt(top=1.0), bsdf)
        if scene == "dressform" and drape is None:
            extra.update(_dressform_props(workdir))
        lo, hi = _bbox(shapes.values())
        floor_y = float(lo[1])
        if scene == "dressform" and drape is None:
            floor_y = 0.0  # the stand's base
            # frame the garment and the torso above it, not the whole stand
            lo = np.minimum(lo, [-0.2, 0.4, -0.2])
            hi = np.maximum(hi, [0.2, 1.45, 0.2])
        if scene == "garment" and framing is None:
            framing = garment_framing()
        if framing is None:
            center = 0.5 * (lo + hi)
            radius = 0.5 * float(np.linalg.norm(hi - lo))
        else:
            center, radius = framing
        d = {"type": "scene"}
        if subject:
            d.update(shapes)
            d.update(extra)
        if floor and opts.floor:
            T = mi.ScalarTransform4f
            d["floor"] = {
                "type": "rectangle",
                "to_world": T().translate([float(center[0]), floor_y - 1e-3, float(center[2])])
                @ T().rotate([1, 0, 0], -90)
                @ T().scale(max(8 * radius, 12.0)),
                "bsdf": _diffuse(STUDIO_FLOOR_ALBEDO if opts.light == "studio" else PROP_ALBEDO),
            }
        if scene == "garment":
            view_dir = (0.12, 0.12, 1.0)  # a fashion shot: nearly level, slightly from the right
            if floor and opts.floor:
                d["backdrop"] = _backdrop(center, radius)
        if opts.grey_card:
            d["grey_card"] = _grey_card(opts, center, radius, view_dir)
        d.update(_lights(opts, center, radius, key_dir))
        d["sensor"] = (_camera(opts, center, radius, view_dir) if meter is None
                       else _meter_camera(opts, center, radius, view_dir, *meter))
        # the studio's soft boxes and strips light the subject; a photographer keeps them out
        # of frame, so the camera does not see emitters directly (their reflections stay)
        integ = opts.integrator or {"type": "path", "max_depth": int(opts.max_depth),
                                    "hide_emitters": opts.light == "studio"}
        if opts.denoise and meter is None:  # colour + first-hit albedo and shading normal for OIDN (render_scene)
            integ = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal", "integrator": integ}
        d["integrator"] = integ
        return _load_dict(d)


def garment_framing():
    """(center, radius) of the garment shot (y up): hem to shoulders of the mannequin."""
    return np.array([0.0, 0.86, 0.0]), 0.62


def _backdrop(center, radius) -> dict:
    """A seamless paper backdrop behind the subject (a curved sweep, dark grey)."""
    n = 24
    t = np.linspace(0.0, np.pi / 2, n)
    R = 0.8
    back = -1.6  # z of the vertical part (y up, camera on +z)
    yz = np.stack([R - R * np.cos(t), back + R - R * np.sin(t)], -1)  # floor -> wall quarter circle
    yz = np.concatenate([[[0.0, 3.0]], yz, [[4.0, back]]])
    xs = np.array([-6.0, 6.0])
    p = np.stack([np.repeat(xs[None, :], len(yz), 0), np.repeat(yz[:, :1], 2, 1), np.repeat(yz[:, 1:], 2, 1)], -1)
    verts = p.reshape(-1, 3)
    i = np.arange(len(yz) - 1)
    faces = np.concatenate([np.stack([2 * i, 2 * i + 1, 2 * i + 3], -1), np.stack([2 * i, 2 * i + 3, 2 * i + 2], -1)])
    v = mi.Float(verts.astype(np.float32).ravel())
    mesh = mi.Mesh("backdrop", len(verts), len(faces))
    params = mi.traverse(mesh)
    params["vertex_positions"] = v
    params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
    params.update()
    mesh.set_bsdf(_load_dict(_diffuse(STUDIO_FLOOR_ALBEDO)))
    return mesh


def scene_framing(drape: Drape):
    """(center, radius) in y-up world covering the first and last frames and colliders."""
    shapes = [_ply_shape(p, _diffuse(), drape.up_axis) for p in (drape.frames[0], drape.frames[-1])]
    shapes += [_ply_shape(c, _diffuse(), drape.up_axis) for c in drape.colliders if c.is_file()]
    lo, hi = _bbox(shapes)
    return 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))


def render_scene(scene: "mi.Scene", opts: RenderOptions) -> np.ndarray:
    """Render to a linear RGB float array (H, W, 3), denoised when ``opts.denoise``.

    With ``denoise`` the scene was loaded with Mitsuba's ``aov`` integrator around the
    path tracer (:func:`load_scene`); its channels are colour, albedo, shading normal,
    and :func:`kesbrdf.render.post.denoise` (Open Image Denoise) uses the last two.
    """
    img = mi.render(scene, spp=int(opts.spp), seed=int(opts.seed))
    dr.eval(img)
    arr = np.array(img, dtype=np.float32)
    if opts.denoise and arr.shape[-1] >= 9:
        from kesbrdf.render.post import denoise

        return denoise(arr[..., :3], arr[..., 3:6], arr[..., 6:9])
    return arr[..., :3]


def to_srgb8(img: np.ndarray, exposure: float = 0.0, tonemap: str = "clip") -> np.ndarray:
    """Linear RGB → 8-bit sRGB, with exposure in stops; ``tonemap`` "clip" or "aces"
    (the filmic curve of :mod:`kesbrdf.render.post`)."""
    if tonemap != "clip":
        from kesbrdf.render.post import to_srgb8 as filmic_srgb8

        return filmic_srgb8(img, exposure, tonemap)
    x = np.clip(np.nan_to_num(img) * (2.0 ** exposure), 0, 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (s * 255 + 0.5).astype(np.uint8)


def save_image(path, img: np.ndarray, metadata: dict | None = None, exposure: float = 0.0,
               tonemap: str = "clip") -> Path:
    """Write a render atomically: ``.exr`` linear, ``.png``/``.jpg`` sRGB 8-bit.

    PNG files carry ``metadata`` as JSON in a ``kesbrdf`` text chunk.
    """
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    from kesbrdf._atomic import atomic_path

    path = Path(path)
    ext = path.suffix.lower()
    with atomic_path(path) as tmp:
        if ext == ".exr":
            mi.Bitmap(np.ascontiguousarray(img, np.float32)).write(str(tmp), mi.Bitmap.FileFormat.OpenEXR)
        elif ext in (".png", ".jpg", ".jpeg"):
            im = Image.fromarray(to_srgb8(img, exposure, tonemap))
            if ext == ".png":
                info = PngInfo()
                if metadata:
                    info.add_text("kesbrdf", json.dumps(metadata, default=str))
                im.save(tmp, format="PNG", pnginfo=info)
            else:
                im.save(tmp, format="JPEG", quality=92)
        else:
            raise KesbrdfError(f"{where(path)}expected an image file ending .png, .jpg or .exr, got {ext or 'no suffix'!r}")
    return path


def provenance(model_path, scene: str, opts: RenderOptions, drape=None) -> dict:
    """What an output records: version, model hash, scene and options."""
    import hashlib

    from kesbrdf._version import __version__

    digest = hashlib.sha256(Path(model_path).read_bytes()).hexdigest() if model_path else None
    return {
        "kesbrdf_version": __version__,
        "model": str(model_path),
        "model_sha256": digest,
        "scene": scene,
        "drape": str(drape.root) if isinstance(drape, Drape) else (str(drape) if drape else None),
        "options": opts.to_json(),
    }


def render_still(model_path, scene: str, output, opts: RenderOptions, drape=None, frame: int | None = None) -> Path:
    """Render one image of ``scene`` to ``output`` (PNG/JPEG/EXR) and return its path."""
    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(model_path))
    if isinstance(drape, (str, Path)):
        drape = read_drape(drape)
    sc = load_scene(model_path, scene, opts, drape=drape, frame=frame)
    img = render_scene(sc, opts)
    return save_image(output, img, provenance(model_path, scene, opts, drape), opts.exposure, opts.tonemap)


def can_denoise() -> bool:
    """True when OIDN (``pyoidn``) is installed, so renders may be denoised."""
    import importlib.util

    return importlib.util.find_spec("pyoidn") is not None


def studio_options(spp: int, resolution=(1280, 720), base_color=None, **kw) -> RenderOptions:
    """The studio look of the demo and the showcase: lights + HDR room, ACES, OIDN when
    installed (docs/rendering.md, "Studio"); ``base_color`` None keeps the measured body."""
    return RenderOptions(spp=spp, resolution=resolution, base_color=base_color, env="studio-hdr",
                         light="studio", tonemap="aces", denoise=can_denoise(), **kw)
