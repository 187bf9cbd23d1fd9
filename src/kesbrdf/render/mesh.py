"""Procedural cloth and garment meshes with warp-carrying UVs (written with :func:`kesbrdf.io.ply.write_ply`).

Every mesh here is ``(positions (V,3), normals (V,3), uvs (V,2), faces (F,3))`` in a
y-up world (metres), with **u along the warp** and v along the weft, oriented so that
∂p/∂u × ∂p/∂v points to the front (the normal); Mitsuba's shading frame
(s = ∂p/∂u, t = n × s, n) is then exactly (warp, weft, normal) (docs/rendering.md).  They
stand in for the cloth simulation's output (``kesbrdf drape``) where none is given.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.io.ply import vertex_normals, write_ply

#: Normal of vertices without a defined one: the render scenes are y-up.
UP = (0.0, 1.0, 0.0)

__all__ = ["grid_faces", "swatch", "folded_cloth", "skirt", "ellipsoid", "rotate_uv", "procedural_drape"]


def grid_faces(n_rows: int, n_cols: int) -> np.ndarray:
    """Two triangles per cell of an (n_rows, n_cols) vertex grid, C-order indices."""
    i, j = np.meshgrid(np.arange(n_rows - 1), np.arange(n_cols - 1), indexing="ij")
    a = (i * n_cols + j).ravel()
    b = a + 1
    c = a + n_cols
    d = c + 1
    return np.concatenate([np.stack([a, c, b], -1), np.stack([b, c, d], -1)]).astype(np.uint32)


def rotate_uv(uv: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate UVs about (0.5, 0.5) by a multiple of 90° (warp → weft for 90°)."""
    k = int(round(degrees / 90.0)) % 4
    u, v = uv[:, 0] - 0.5, uv[:, 1] - 0.5
    for _ in range(k):
        u, v = -v, u
    return np.stack([u + 0.5, v + 0.5], -1)


def _grid_mesh(pos_fn, n_u: int, n_v: int):
    u, v = np.meshgrid(np.linspace(0, 1, n_u), np.linspace(0, 1, n_v), indexing="ij")
    positions = pos_fn(u, v).reshape(-1, 3)
    uv = np.stack([u, v], -1).reshape(-1, 2)
    faces = grid_faces(n_u, n_v)
    return positions, vertex_normals(positions, faces, fallback=UP), uv, faces


def swatch(size: float = 1.0, bend: float = 0.0, n: int = 33):
    """A square swatch in the x–z plane (normal +y), optionally bent about the z axis.

    u runs along +x (the warp), v along −z (the weft) before any bend, so that
    ∂p/∂u × ∂p/∂v is the normal and Mitsuba's frame (s, n × s, n) is (u, v, n).
    """

    def pos(u, v):
        x = (u - 0.5) * size
        z = (0.5 - v) * size
        if bend:
            radius = size / bend
            angle = x / radius
            return np.stack([radius * np.sin(angle), radius * (np.cos(angle) - 1), z], -1)
        return np.stack([x, np.zeros_like(x), z], -1)

    return _grid_mesh(pos, n, n)


def folded_cloth(size: float = 1.2, n: int = 65, folds: int = 3, amplitude: float = 0.05):
    """A sheet with soft folds lying over a low dome: a stand-in for a draped frame.

    u (warp) runs across the folds (along x), v along them (along −z).
    """

    def pos(u, v):
        x = (u - 0.5) * size
        z = (0.5 - v) * size
        r2 = (x**2 + z**2) / (0.5 * size) ** 2
        dome = 0.25 * size * np.exp(-2.5 * r2)
        fold = amplitude * size * np.sin(2 * math.pi * folds * u + 1.3 * np.sin(math.pi * v)) * (0.4 + 0.6 * r2)
        return np.stack([x, dome + fold, z], -1)

    return _grid_mesh(pos, n, n)


def skirt(waist_radius: float = 0.16, hem_radius: float = 0.34, length: float = 0.55, top: float = 1.0,
          folds: int = 9, amplitude: float = 0.035, n_u: int = 40, n_v: int = 145):
    """A flared skirt with vertical folds; u (warp) runs from waist to hem, v around.

    The seam at v = 0 ≡ 1 repeats its vertices (UVs differ there).
    """

    def pos(u, v):
        theta = 2 * math.pi * v
        r = waist_radius + (hem_radius - waist_radius) * u ** 0.8 + amplitude * u * np.sin(folds * theta)
        y = top - length * u
        return np.stack([r * np.sin(theta), y, r * np.cos(theta)], -1)

    return _grid_mesh(pos, n_u, n_v)


def ellipsoid(center=(0.0, 0.0, 0.0), radii=(1.0, 1.0, 1.0), n_u: int = 24, n_v: int = 48):
    """A UV ellipsoid (y axis vertical); u from top to bottom, v around."""

    def pos(u, v):
        theta = math.pi * u
        phi = 2 * math.pi * v
        unit = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1)
        return np.asarray(center) + unit * np.asarray(radii)

    p, _, uv, f = _grid_mesh(pos, n_u, n_v)
    # analytic normals (the seam and poles repeat vertices)
    theta, phi = math.pi * uv[:, 0], 2 * math.pi * uv[:, 1]
    unit = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1)
    n = unit / np.asarray(radii)
    return p, n / np.linalg.norm(n, axis=-1, keepdims=True), uv, f


def procedural_drape(folder, frames: int = 24, fps: float = 24.0, n: int = 49):
    """Write a drape folder (``kesbrdf drape`` format) of a sheet settling into folds.

    A stand-in when the cloth simulator is not installed: the sheet falls onto a low
    dome and its folds grow over the sequence.  z-up like newton's output
    (``"up_axis": "z"``).  Returns the folder path.
    """
    import json
    from pathlib import Path

    from kesbrdf._atomic import write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for k in range(frames):
        t = k / max(frames - 1, 1)
        ease = t * t * (3 - 2 * t)
        p, _, uv, f = folded_cloth(n=n, amplitude=0.05 * ease)
        p = p * [1.0, ease, 1.0] + [0.0, 0.6 * (1 - ease), 0.0]
        zup = np.stack([p[:, 0], -p[:, 2], p[:, 1]], -1)  # y-up -> z-up
        name = f"frame_{k:04d}.ply"
        write_ply(folder / name, zup, f, vertex_normals(zup, f), uv)
        names.append(name)
    meta = {"fps": fps, "frames": names, "colliders": [], "scene": "sphere", "up_axis": "z",
            "generator": "kesbrdf.render.mesh.procedural_drape"}
    write_text(folder / "drape.json", json.dumps(meta, indent=1) + "\n")
    return folder
