"""A cloth piece: a structured grid of particles with lumped masses and springs (numpy only).

:class:`ClothPiece` is what the drape solver (:mod:`kesbrdf.cloth.drape`) simulates and
:func:`grid_piece` assembles one from an ``(n_i, n_j)`` grid of rest points: triangles
with alternating diagonals, masses lumped from the cell areas (areal density ρ), and
springs assembled cell by cell so that a square cell gives the sheet a tensile stiffness
E·t along the grid axes and ``shear``·E·t across its diagonals (docs/drape.md).

A **bias-cut** piece (``bias=True``) has its threads along the cell diagonals, at 45° to
the grid: the diagonals then carry the tensile stiffness and the grid axes the shear
stiffness, so the panel is compliant along the grid (bias stretch), as cloth cut on the
bias is.  Both layouts keep the same total stiffness per cell.

Used by :mod:`kesbrdf.cloth.scenes` (sheet, skirt) and :mod:`kesbrdf.cloth.pattern` (the
sewn skirt's panels); this module imports neither, so they do not import each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ClothPiece", "grid_piece", "BIAS_AXIS_FRACTION"]

#: Tensile stiffness along the grid axes of a bias-cut piece, as a fraction of E·t.
#: A woven fabric pulled at 45° to its threads is resisted by shear and thread
#: rotation only: its bias modulus is a fraction of the thread modulus.  0.5 keeps the
#: per-particle stiffness sum (hence the XPBD substep) that of a straight-grain piece
#: (4 axis springs of 0.5 E·t and 4 diagonals of 0.5 E·t against 4 of E·t and 4 of
#: 0.05 E·t); the sewn panel's seams are taped (kesbrdf.cloth.pattern.BIAS_SEAM_FACTOR)
#: so that they hold within the seam tolerance (tests/cloth/test_garment.py).
BIAS_AXIS_FRACTION = 0.5


@dataclass
class ClothPiece:
    """A cloth grid: rest positions, triangles, UVs, springs, pinned vertices.

    positions : (n_i * n_j, 3) rest = initial positions [m], row-major in (i, j).
    faces : (M, 3) int32 simulation triangles (periodic in j when ``closed``).
    masses : (N,) lumped particle masses [kg] (a quarter of each incident cell).
    springs : (S, 2) int32 particle pairs; spring_ke (S,) stiffness [N/m].
    pinned : (N,) bool, vertices held in place (kinematic).
    closed : the weft wraps around (a tube); output duplicates the seam column.
    """

    shape: tuple[int, int]
    positions: np.ndarray
    faces: np.ndarray
    uv_rest: np.ndarray
    masses: np.ndarray
    springs: np.ndarray
    spring_ke: np.ndarray
    min_spring_length: float
    pinned: np.ndarray
    closed: bool = False
    output_index: np.ndarray = field(default=None)  # (n_out,) simulation vertex of each output vertex
    output_uv: np.ndarray = field(default=None)
    output_faces: np.ndarray = field(default=None)
    # sewn garments (kesbrdf.cloth.pattern): rest lengths from the flat pattern, flat
    # bending rest angles, stitched vertex pairs and their contact radius [m]
    spring_rest: np.ndarray | None = None
    flat_rest: bool = False
    seams: np.ndarray | None = None
    seam_radius: float | None = None
    panels: int = 1
    bias_gores: tuple = ()
    clearance: dict | None = None



def grid_piece(points: np.ndarray, uv: np.ndarray, closed: bool, density: float, stretch: float, shear: float,
               bias: bool = False) -> ClothPiece:
    """Faces, lumped masses and springs of an (n_i, n_j) grid of rest points (``bias``: module docstring)."""
    n_i, n_j = points.shape[:2]
    idx = np.arange(n_i * n_j).reshape(n_i, n_j)
    cells_j = n_j if closed else n_j - 1
    ii, jj = np.meshgrid(np.arange(n_i - 1), np.arange(cells_j), indexing="ij")
    a = idx[ii, jj]
    b = idx[ii + 1, jj]
    c = idx[ii + 1, (jj + 1) % n_j]
    d = idx[ii, (jj + 1) % n_j]
    # alternate the diagonal (no preferred shear direction); winding: du x dv = normal
    even = ((ii + jj) % 2 == 0)[..., None]
    t1 = np.where(even, np.stack([a, b, c], -1), np.stack([a, b, d], -1))
    t2 = np.where(even, np.stack([a, c, d], -1), np.stack([b, c, d], -1))
    faces = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)]).astype(np.int32)

    p = points.reshape(-1, 3).astype(np.float64)
    A = np.linalg.norm(np.cross(p[b] - p[a], p[d] - p[a]), axis=-1)  # cell area (parallelogram)
    masses = np.zeros(n_i * n_j)
    for corner in (a, b, c, d):
        np.add.at(masses, corner.ravel(), density * A.ravel() / 4.0)

    # springs assembled cell by cell: an edge of length L in a cell of area A gets
    # k = E_t * A / (2 L^2) from that cell (interior edges are shared by two cells, so
    # a square interior cell edge ends up with k = E_t); each diagonal k = s E_t A / L^2
    ke: dict[tuple[int, int], float] = {}

    def add(i0, i1, coeff):
        L2 = np.sum((p[i1] - p[i0]) ** 2, axis=-1)
        for x, y, k in zip(i0.ravel(), i1.ravel(), (coeff * A / L2).ravel()):
            key = (x, y) if x < y else (y, x)
            ke[key] = ke.get(key, 0.0) + float(k)

    if not bias:
        for e0, e1 in ((a, b), (b, c), (c, d), (d, a)):
            add(e0, e1, 0.5 * stretch)
        if shear > 0:
            add(a, c, shear * stretch)
            add(b, d, shear * stretch)
    else:
        # threads along the diagonals: a diagonal of a square cell (L² = 2A) with
        # k = E_t A / L² = E_t / 2, one per cell, spaced h/√2, is a tensile stiffness E_t
        # along it; the grid axes (45° to the threads) get BIAS_AXIS_FRACTION of E_t
        add(a, c, stretch)
        add(b, d, stretch)
        for e0, e1 in ((a, b), (b, c), (c, d), (d, a)):
            add(e0, e1, 0.5 * BIAS_AXIS_FRACTION * stretch)
    springs = np.array(list(ke.keys()), dtype=np.int32)
    spring_ke = np.array(list(ke.values()))
    lengths = np.linalg.norm(p[springs[:, 0]] - p[springs[:, 1]], axis=-1)

    piece = ClothPiece(
        shape=(n_i, n_j), positions=p.astype(np.float32), faces=faces, uv_rest=uv.reshape(-1, 2),
        masses=masses, springs=springs, spring_ke=spring_ke, min_spring_length=float(lengths.min()),
        pinned=np.zeros(n_i * n_j, bool), closed=closed,
    )
    if closed:  # duplicate the seam column so v can run 0 .. circumference
        out_idx = np.concatenate([idx, idx[:, :1]], axis=1)
        seam = uv[:, :1].copy()
        seam[:, 0, 1] = 2 * uv[:, -1, 1] - uv[:, -2, 1]  # one more weft step past the last column
        out_uv = np.concatenate([uv, seam], axis=1)
        o = np.arange(n_i * (n_j + 1)).reshape(n_i, n_j + 1)
        oi, oj = np.meshgrid(np.arange(n_i - 1), np.arange(n_j), indexing="ij")
        oa, ob, oc, od = o[oi, oj], o[oi + 1, oj], o[oi + 1, oj + 1], o[oi, oj + 1]
        t1 = np.where(even, np.stack([oa, ob, oc], -1), np.stack([oa, ob, od], -1))
        t2 = np.where(even, np.stack([oa, oc, od], -1), np.stack([ob, oc, od], -1))
        piece.output_index = out_idx.ravel()
        piece.output_uv = out_uv.reshape(-1, 2).astype(np.float32)
        piece.output_faces = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)]).astype(np.int32)
    else:
        piece.output_index = np.arange(n_i * n_j)
        piece.output_uv = piece.uv_rest.astype(np.float32)
        piece.output_faces = faces
    return piece
