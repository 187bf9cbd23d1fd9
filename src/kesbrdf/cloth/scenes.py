"""Cloth pieces and collider primitives for the two drape scenes (numpy only).

World frame: metres, **z up**, floor at z = 0 (newton's default up axis).

* ``sphere``: a square satin sheet, warp along world x, held flat above a sphere that
  stands on the floor.
* ``dressform``: an A-line skirt (a cone frustum of cloth, warp running down the skirt)
  whose waist edge is pinned just outside the waist of a dress form built from
  capsules (hips, torso, bust, shoulders, neck, stand) and a box (base).
* ``garment``: a six-gore skirt cut from flat pattern panels and sewn at its seams
  (:mod:`kesbrdf.cloth.pattern`) on a smooth procedural mannequin
  (:mod:`kesbrdf.cloth.mannequin`, a triangle-mesh collider that can turn about z).

Cloth grids are indexed ``(i, j)``: ``i`` runs along the **warp** (the grid's first axis),
``j`` along the **weft**.  Texture coordinates are rest-state arc lengths in metres:
``u`` along the warp from the first row, ``v`` along the weft from the first column;
faces are wound so that ``∂p/∂u × ∂p/∂v`` points along the face normal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kesbrdf.cloth import pattern as _pattern
from kesbrdf.cloth.grid import ClothPiece, grid_piece

#: The grid assembler under its former name (kept for callers of ``scenes._grid``).
_grid = grid_piece

__all__ = ["Collider", "ClothPiece", "SceneSpec", "sheet", "skirt", "sphere_scene", "dressform_scene",
           "garment_scene", "collider_mesh", "signed_distance"]


@dataclass(frozen=True)
class Collider:
    """A static collision primitive.

    kind : ``"sphere"`` (center, radius), ``"capsule"`` (center, unit axis, radius,
    half_height of the cylindrical part), ``"box"`` (center, half_extents, axis-aligned)
    or ``"mesh"`` (the procedural mannequin of :mod:`kesbrdf.cloth.mannequin`; it turns
    with the scene's body rotation when ``moves`` is true).
    """

    kind: str
    center: tuple[float, float, float]
    radius: float = 0.0
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    half_height: float = 0.0
    half_extents: tuple[float, float, float] = (0.0, 0.0, 0.0)
    label: str = ""
    moves: bool = False

    def to_json(self) -> dict:
        d = {"kind": self.kind, "label": self.label, "center": list(self.center)}
        if self.kind in ("sphere", "capsule"):
            d["radius"] = self.radius
        if self.kind == "capsule":
            d["axis"] = list(self.axis)
            d["half_height"] = self.half_height
        if self.kind == "box":
            d["half_extents"] = list(self.half_extents)
        if self.kind == "mesh":
            d["source"] = "kesbrdf.cloth.mannequin (procedural)"
            d["moves"] = bool(self.moves)
        return d


@dataclass
class SceneSpec:
    name: str
    cloth: ClothPiece
    colliders: list[Collider]
    ground_height: float = 0.0


def sheet(n: int, size: float, height: float, density: float, stretch: float, shear: float) -> ClothPiece:
    """A flat square sheet of ``n × n`` cells, centred on the z axis at ``height``.

    The warp (grid axis i, texture u) runs along world +x, the weft along +y.
    """
    t = np.linspace(0.0, size, n + 1)
    ii, jj = np.meshgrid(t, t, indexing="ij")
    pts = np.stack([ii - size / 2, jj - size / 2, np.full_like(ii, height)], -1)
    uv = np.stack([ii, jj], -1)
    return _grid(pts, uv, False, density, stretch, shear)


def skirt(n_length: int, n_around: int, waist_z: float, waist_radius: float, hem_radius: float,
          length: float, density: float, stretch: float, shear: float) -> ClothPiece:
    """An A-line skirt: a cone frustum from the waist down, waist row pinned.

    Rows ``i`` run down the skirt along the warp (u = slant distance from the waist),
    columns ``j`` counter-clockwise around it along the weft (v = arc length at that
    row's rest radius), so ``∂p/∂u × ∂p/∂v`` points outward.
    """
    s = np.linspace(0.0, 1.0, n_length + 1)
    r = waist_radius + (hem_radius - waist_radius) * s
    z = waist_z - length * s
    theta = np.arange(n_around) * (2 * np.pi / n_around)
    R, TH = np.meshgrid(r, theta, indexing="ij")
    Z = np.broadcast_to(z[:, None], R.shape)
    pts = np.stack([R * np.cos(TH), R * np.sin(TH), Z], -1)
    slant = np.hypot(length, hem_radius - waist_radius)
    uv = np.stack([np.broadcast_to((s * slant)[:, None], R.shape), R * TH], -1)
    piece = _grid(pts, uv, True, density, stretch, shear)
    piece.pinned[: n_around] = True
    return piece


def sphere_scene(resolution: int, density: float, stretch: float, shear: float) -> SceneSpec:
    """A 1 m satin sheet held 0.15 m above a 0.3 m sphere resting on the floor."""
    radius = 0.3
    cloth = sheet(resolution, size=1.0, height=2 * radius + 0.15, density=density, stretch=stretch, shear=shear)
    return SceneSpec("sphere", cloth, [Collider("sphere", (0.0, 0.0, radius), radius=radius, label="sphere")])


#: The dress form (z up, metres): capsules (center, axis, radius, half_height) and a base box.
DRESS_FORM: tuple[Collider, ...] = (
    Collider("capsule", (0.0, 0.0, 0.86), 0.14, (1.0, 0.0, 0.0), 0.05, label="hips"),
    Collider("capsule", (0.0, 0.0, 1.08), 0.12, (0.0, 0.0, 1.0), 0.12, label="torso"),
    Collider("capsule", (0.0, 0.01, 1.22), 0.125, (1.0, 0.0, 0.0), 0.06, label="bust"),
    Collider("capsule", (0.0, 0.0, 1.36), 0.075, (1.0, 0.0, 0.0), 0.13, label="shoulders"),
    Collider("capsule", (0.0, 0.0, 1.47), 0.045, (0.0, 0.0, 1.0), 0.04, label="neck"),
    Collider("capsule", (0.0, 0.0, 0.40), 0.02, (0.0, 0.0, 1.0), 0.36, label="stand"),
    Collider("box", (0.0, 0.0, 0.01), half_extents=(0.18, 0.18, 0.01), label="base"),
)


def dressform_scene(resolution: int, density: float, stretch: float, shear: float) -> SceneSpec:
    """An A-line skirt (0.55 m long) pinned at the waist (z = 1.0 m) of the dress form.

    ``resolution`` cells around the hem are ``2 × resolution``; rows down the skirt
    are ``resolution // 2`` (cells of a few centimetres at the default 48).
    """
    cloth = skirt(max(resolution // 2, 2), 2 * resolution, waist_z=1.0, waist_radius=0.125,
                  hem_radius=0.42, length=0.55, density=density, stretch=stretch, shear=shear)
    return SceneSpec("dressform", cloth, list(DRESS_FORM))


#: The mannequin's stand (static: the body turns on it).
MANNEQUIN_STAND: tuple[Collider, ...] = (
    Collider("capsule", (0.0, 0.0, 0.30), 0.018, (0.0, 0.0, 1.0), 0.27, label="stand"),
    Collider("box", (0.0, 0.0, 0.012), half_extents=(0.2, 0.2, 0.012), label="base"),
)


def garment_scene(resolution: int, density: float, stretch: float, shear: float) -> SceneSpec:
    """A six-gore skirt sewn from pattern panels on the procedural mannequin.

    ``resolution`` 48 gives 24 rows down and 8 cells across each gore (``resolution // 2``
    and ``max(resolution // 6, 3)``).
    """
    cloth = _pattern.gored_skirt(max(resolution // 2, 4), max(resolution // 4, 3), density, stretch, shear)
    body = Collider("mesh", (0.0, 0.0, 0.0), label="mannequin", moves=True)
    return SceneSpec("garment", cloth, [body, *MANNEQUIN_STAND])


# -- collider geometry ----------------------------------------------------------------
def _frame(axis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1), a


def collider_mesh(c: Collider, segments: int = 48):
    """Triangulate a collider: ``(vertices, normals, uv, faces)`` with outward normals."""
    if c.kind == "mesh":
        from kesbrdf.cloth.mannequin import mannequin_mesh

        return mannequin_mesh()
    if c.kind == "box":
        h = np.asarray(c.half_extents, float)
        verts, norms, uvs, faces = [], [], [], []
        for ax in range(3):
            for sign in (-1.0, 1.0):
                n = np.zeros(3)
                n[ax] = sign
                t1 = np.zeros(3)
                t1[(ax + 1) % 3] = 1.0
                t2 = np.cross(n, t1)
                base = len(verts)
                for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                    verts.append(np.asarray(c.center) + h * (n + du * t1 + dv * t2))
                    norms.append(n)
                    uvs.append(((du + 1) / 2, (dv + 1) / 2))
                faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
        return (np.array(verts, np.float32), np.array(norms, np.float32), np.array(uvs, np.float32),
                np.array(faces, np.int32))
    e1, e2, a = _frame(c.axis if c.kind == "capsule" else (0.0, 0.0, 1.0))
    half = c.half_height if c.kind == "capsule" else 0.0
    n_lat = segments // 2
    lat = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)
    # split the equator so a capsule's cylinder sits between its two caps
    rows = [(l, -half if l < 0 else half) for l in lat[lat < 0]] + [(0.0, -half), (0.0, half)] + \
        [(l, half) for l in lat[lat > 0]]
    phi = np.linspace(0.0, 2 * np.pi, segments + 1)
    L = np.array([r[0] for r in rows])[:, None]
    off = np.array([r[1] for r in rows])[:, None, None]
    P = np.cos(phi)[None, :, None] * e1 + np.sin(phi)[None, :, None] * e2
    normal = np.cos(L)[..., None] * P + np.sin(L)[..., None] * a
    pos = np.asarray(c.center) + c.radius * normal + off * a
    n_r, n_c = normal.shape[:2]
    o = np.arange(n_r * n_c).reshape(n_r, n_c)
    ii, jj = np.meshgrid(np.arange(n_r - 1), np.arange(n_c - 1), indexing="ij")
    q = o[ii, jj], o[ii, jj + 1], o[ii + 1, jj + 1], o[ii + 1, jj]
    faces = np.concatenate([np.stack([q[0], q[1], q[2]], -1).reshape(-1, 3),
                            np.stack([q[0], q[2], q[3]], -1).reshape(-1, 3)])
    verts = pos.reshape(-1, 3)
    area = np.linalg.norm(np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]]), axis=-1)
    faces = faces[area > 1e-12]  # drop the collapsed triangles at the poles
    uv = np.stack(np.meshgrid(np.linspace(0, 1, n_r), phi / (2 * np.pi), indexing="ij")[::-1], -1).reshape(-1, 2)
    return verts.astype(np.float32), normal.reshape(-1, 3).astype(np.float32), uv.astype(np.float32), faces.astype(np.int32)


def signed_distance(c: Collider, points, rotation_z: float = 0.0) -> np.ndarray:
    """Signed distance [m] from points (..., 3) to the collider's surface (< 0 inside).

    For the mannequin (``"mesh"``) only the inside is measured (minus the depth of
    :func:`kesbrdf.cloth.mannequin.inside_depth`, 0 outside), with the body turned by
    ``rotation_z`` [rad].
    """
    if c.kind == "mesh":
        from kesbrdf.cloth.mannequin import inside_depth

        return -inside_depth(points, rotation_z)
    p = np.asarray(points, float) - np.asarray(c.center, float)
    if c.kind == "sphere":
        return np.linalg.norm(p, axis=-1) - c.radius
    if c.kind == "capsule":
        a = np.asarray(c.axis, float) / np.linalg.norm(c.axis)
        t = np.clip(p @ a, -c.half_height, c.half_height)
        return np.linalg.norm(p - t[..., None] * a, axis=-1) - c.radius
    if c.kind == "box":
        q = np.abs(p) - np.asarray(c.half_extents, float)
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        return outside + np.minimum(q.max(axis=-1), 0.0)
    raise ValueError(f"unknown collider kind {c.kind!r}")
