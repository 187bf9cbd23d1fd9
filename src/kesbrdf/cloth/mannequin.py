"""A smooth procedural mannequin: a lofted body of elliptical cross-sections (numpy only).

Provenance: made here, from the table :data:`PROFILE` below (no scan, no download).  The
body is the surface swept by an ellipse whose semi-axes ``a(z)`` (across, world x) and
``b(z)`` (front to back, world y) and centre offset ``c(z)`` (along y) vary smoothly with
the height z: shape-preserving cubic (PCHIP) interpolation through the control rows, so
the surface has no overshoot between them and is C¹ everywhere.  The measurements are
those of a women's dress form of about EU size 38: bust 0.89 m, waist 0.68 m, hips
0.95 m (ellipse perimeters, Ramanujan's formula).  World frame as the drape scenes:
metres, z up; the front of the body faces **−y** (the camera side once the renderer turns
z-up into y-up).

The mesh is closed (fan caps at the neck and below the hips), its faces wound with
outward normals, so newton can use it as a mesh collider and Mitsuba can render it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import PchipInterpolator

__all__ = ["PROFILE", "Profile", "profile", "mannequin_mesh", "ellipse_perimeter", "inside_depth"]

#: Control rows of the body: height z [m], half-width a [m] (x), half-depth b [m] (y),
#: centre offset c [m] along y (negative: forward).  Bottom (upper thigh) to neck top.
PROFILE = np.array([
    # z      a       b       c
    (0.560, 0.150, 0.105, 0.004),
    (0.640, 0.165, 0.118, 0.008),
    (0.780, 0.176, 0.126, 0.012),   # hips / seat (fullest)
    (0.880, 0.158, 0.112, 0.006),   # high hip
    (1.000, 0.125, 0.090, 0.000),   # waist
    (1.110, 0.138, 0.100, -0.008),  # under bust
    (1.210, 0.160, 0.124, -0.018),  # bust
    (1.320, 0.162, 0.104, -0.006),  # chest
    (1.400, 0.168, 0.082, 0.000),   # shoulders
    (1.450, 0.120, 0.068, 0.000),   # shoulder slope
    (1.485, 0.058, 0.052, 0.000),   # base of the neck
    (1.560, 0.050, 0.048, 0.004),   # neck
    (1.585, 0.045, 0.043, 0.004),   # neck top
])
#: Height of the waist [m] (where the skirt's waistband sits).
WAIST_Z = 1.0


def ellipse_perimeter(a, b):
    """Ramanujan's second approximation of an ellipse's perimeter (relative error < 1e-9 here)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    h = ((a - b) / (a + b)) ** 2
    return math.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))


class Profile:
    """Smooth semi-axes a(z), b(z) and offset c(z) of the body's cross-sections."""

    def __init__(self, table=PROFILE):
        t = np.asarray(table, float)
        self.z_min, self.z_max = float(t[0, 0]), float(t[-1, 0])
        self._a = PchipInterpolator(t[:, 0], t[:, 1])
        self._b = PchipInterpolator(t[:, 0], t[:, 2])
        self._c = PchipInterpolator(t[:, 0], t[:, 3])

    def __call__(self, z):
        """(a, b, c) at heights z, held constant outside [z_min, z_max]."""
        zc = np.clip(np.asarray(z, float), self.z_min, self.z_max)
        return self._a(zc), self._b(zc), self._c(zc)


def profile() -> Profile:
    return Profile()


def mannequin_mesh(rings: int = 72, segments: int = 64, rotation_z: float = 0.0):
    """The body as a closed triangle mesh: ``(vertices, normals, uv, faces)``.

    ``rings`` cross-sections from the bottom to the top of :data:`PROFILE` (denser where
    the profile bends), ``segments`` vertices around each; ``rotation_z`` turns the body
    about the z axis [rad].  Normals are the area-weighted vertex normals.
    """
    from kesbrdf.cloth.ply import vertex_normals

    prof = profile()
    s = np.linspace(0.0, 1.0, rings)
    z = prof.z_min + (prof.z_max - prof.z_min) * (0.5 - 0.5 * np.cos(np.pi * s))  # denser at the ends
    a, b, c = prof(z)
    th = np.arange(segments) * (2 * np.pi / segments)
    x = a[:, None] * np.cos(th)[None, :]
    y = c[:, None] + b[:, None] * np.sin(th)[None, :]
    zz = np.broadcast_to(z[:, None], x.shape)
    ring = np.stack([x, y, zz], -1).reshape(-1, 3)
    bottom = np.array([[0.0, float(c[0]), float(z[0])]])
    top = np.array([[0.0, float(c[-1]), float(z[-1])]])
    verts = np.concatenate([ring, bottom, top])
    o = np.arange(rings * segments).reshape(rings, segments)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    p00, p01 = o[i, j], o[i, (j + 1) % segments]
    p10, p11 = o[i + 1, j], o[i + 1, (j + 1) % segments]
    # theta increases counter-clockwise seen from above, z up: (p01 - p00) x (p10 - p00) points out
    side = np.concatenate([np.stack([p00, p01, p11], -1).reshape(-1, 3),
                           np.stack([p00, p11, p10], -1).reshape(-1, 3)])
    nb, nt = rings * segments, rings * segments + 1
    jj = np.arange(segments)
    cap_b = np.stack([np.full(segments, nb), o[0, (jj + 1) % segments], o[0, jj]], -1)
    cap_t = np.stack([np.full(segments, nt), o[-1, jj], o[-1, (jj + 1) % segments]], -1)
    faces = np.concatenate([side, cap_b, cap_t]).astype(np.int32)
    if rotation_z:
        cr, sr = math.cos(rotation_z), math.sin(rotation_z)
        verts = verts @ np.array([[cr, sr, 0.0], [-sr, cr, 0.0], [0.0, 0.0, 1.0]])
    verts = verts.astype(np.float32)
    normals = vertex_normals(verts, faces)
    uv = np.zeros((len(verts), 2), np.float32)
    uv[: rings * segments, 0] = np.repeat(s, segments)
    uv[: rings * segments, 1] = np.tile(th / (2 * np.pi), rings)
    return verts, normals.astype(np.float32), uv, faces


def inside_depth(points, rotation_z: float = 0.0) -> np.ndarray:
    """How deep points (..., 3) lie inside the body [m]; 0 outside (≤ 0 never returned).

    Measured in the horizontal cross-section at each point's height: with the
    elliptical radius ρ = ‖((x / a), (y − c) / b)‖ (body frame), a point is inside when
    ρ < 1 and its depth is (1 − ρ)·min(a, b), a lower bound of the true distance to
    the surface within about 30 % where the section is most elongated (a/b = 1.5).
    Points above or below the body count as outside.
    """
    p = np.asarray(points, float)
    cr, sr = math.cos(-rotation_z), math.sin(-rotation_z)
    x = cr * p[..., 0] - sr * p[..., 1]
    y = sr * p[..., 0] + cr * p[..., 1]
    prof = profile()
    a, b, c = prof(p[..., 2])
    rho = np.hypot(x / a, (y - c) / b)
    inside = (rho < 1.0) & (p[..., 2] >= prof.z_min) & (p[..., 2] <= prof.z_max)
    return np.where(inside, (1.0 - rho) * np.minimum(a, b), 0.0)
