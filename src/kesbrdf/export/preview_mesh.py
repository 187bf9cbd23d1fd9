"""Preview meshes for material exports: a fabric swatch and a UV sphere with warp tangents.

Both are in glTF's frame (y up, metres).  The fabric frame maps onto each vertex as
x = warp = TANGENT, z = normal = NORMAL, y = weft = bitangent = NORMAL × TANGENT
(TANGENT.w = +1, the glTF bitangent rule).

- swatch: a square of side ``size`` in the y = 0 plane, normal +Y, warp along +X
  (so the weft runs along −Z), UV u along the warp;
- sphere: warp along the parallels (∂/∂φ, around the +Y axis), so the weft runs
  along the meridians; UV (φ/2π, θ/π).  The seam and the poles repeat vertices, each
  with its own tangent, so every TANGENT is defined and unit length.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Mesh", "swatch", "uv_sphere"]


@dataclasses.dataclass
class Mesh:
    """Float32 vertex attributes and uint32 triangle indices."""

    name: str
    positions: np.ndarray  # (V, 3)
    normals: np.ndarray  # (V, 3)
    tangents: np.ndarray  # (V, 4), w = ±1
    uvs: np.ndarray  # (V, 2)
    indices: np.ndarray  # (T*3,)


def swatch(size: float = 1.0, n: int = 2) -> Mesh:
    """A flat square swatch of ``n`` × ``n`` vertices (see module docstring)."""
    u = np.linspace(0.0, 1.0, n)
    uu, vv = np.meshgrid(u, u, indexing="xy")
    x = (uu - 0.5) * size
    z = (vv - 0.5) * size
    positions = np.stack([x, np.zeros_like(x), z], -1).reshape(-1, 3)
    normals = np.tile([0.0, 1.0, 0.0], (positions.shape[0], 1))
    tangents = np.tile([1.0, 0.0, 0.0, 1.0], (positions.shape[0], 1))
    uvs = np.stack([uu, vv], -1).reshape(-1, 2)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    # counter-clockwise seen from +Y: (a, c, b) and (b, c, d) with rows along +z
    tris = np.stack([a, c, b, b, c, d], -1).reshape(-1)
    return Mesh("swatch", positions.astype(np.float32), normals.astype(np.float32), tangents.astype(np.float32), uvs.astype(np.float32), tris.astype(np.uint32))


def uv_sphere(radius: float = 0.5, n_theta: int = 32, n_phi: int = 64, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A UV sphere with the warp along the parallels (see module docstring)."""
    theta = np.linspace(0.0, np.pi, n_theta + 1)
    phi = np.linspace(0.0, 2 * np.pi, n_phi + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    normal = np.stack([np.sin(th) * np.cos(ph), np.cos(th), -np.sin(th) * np.sin(ph)], -1)
    # ∂/∂φ direction (unit, defined at the poles too)
    tangent = np.stack([-np.sin(ph), np.zeros_like(ph), -np.cos(ph)], -1)
    positions = radius * normal + np.asarray(center, float)
    uvs = np.stack([ph / (2 * np.pi), th / np.pi], -1)
    idx = np.arange((n_theta + 1) * (n_phi + 1)).reshape(n_theta + 1, n_phi + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    quads = np.stack([a, c, b, b, c, d], -1)
    # drop the degenerate triangles at the poles (zero area)
    tris = np.concatenate([quads[1:-1].reshape(-1, 6), quads[0][:, 3:], quads[-1][:, :3]], axis=None)
    t4 = np.concatenate([tangent, np.ones(tangent.shape[:-1] + (1,))], -1)
    return Mesh(
        "sphere",
        positions.reshape(-1, 3).astype(np.float32),
        normal.reshape(-1, 3).astype(np.float32),
        t4.reshape(-1, 4).astype(np.float32),
        uvs.reshape(-1, 2).astype(np.float32),
        tris.astype(np.uint32),
    )
