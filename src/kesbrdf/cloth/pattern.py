"""A gored skirt from flat pattern panels, placed around the mannequin and sewn at the seams.

The garment is cut as a tailor would cut it (docs/drape.md, "Pattern panels"):

* **Panels.** ``gores`` identical gores (default six: centre front, two front sides,
  centre back, two back sides).  In pattern space a gore is symmetric about its
  vertical centre line, the **grain line**: x across (metres from the centre line),
  y down from the waist (metres).  Its half-width at depth y is ``C(y) / (2·gores)``
  for the skirt's circumference C(y) (:func:`circumference`): fitted to the body plus
  ease above the hip line, then a straight flare to the hem.  The side seams are
  therefore curved above the hip and straight below, as in a paper pattern.
* **Triangulation.** Each gore is a structured grid of ``rows × cols`` cells in
  (y, x/half-width), triangles with alternating diagonals.  Masses and spring
  stiffnesses are assembled from the *flat* pattern (:func:`kesbrdf.cloth.scenes._grid`),
  so the rest state of every spring is its length in the pattern and the rest angle of
  every bending hinge is 0 (flat cloth).
* **Grain-line UVs.** u = y (distance down the grain line, the warp), v = x + half the
  widest width (across the grain, the weft), both in metres of flat fabric: the
  ``kesbrdf`` BSDF's x axis (warp, ∂p/∂u) runs along each gore's own grain line, so the
  warp of neighbouring gores meets at an angle at every seam, as in a real gored skirt.
  ∂p/∂u × ∂p/∂v points out of the garment.
* **Bias cut.** The gores in ``bias_gores`` (default: the centre front) are cut on the
  bias: their grain line runs at 45° to the gore's centre line.  Their UVs are the
  straight-grain ones turned by +45° in pattern space, u' = (u + v)/√2,
  v' = (v − u)/√2 (a rotation, so ∂p/∂u' × ∂p/∂v' still points out and the BSDF's warp
  follows the bias grain), and their springs are assembled with the threads along the
  cell diagonals (:func:`kesbrdf.cloth.grid.grid_piece` with ``bias=True``): the panel
  is compliant down its length and drapes in softer, rounder folds than its neighbours.
* **Placement.** Row y of every gore is laid on one horizontal ellipse around the body
  (the body's cross-section at that height, grown until its perimeter is C(y) plus one
  seam gap per seam), gore k centred on the arc at k/gores of the way round from the
  centre front; the heights follow the meridian so that the placed panel is nearly
  isometric to the pattern.  Below the hip line only ``hang_flare`` of the flare goes
  into the mean girth: the rest is laid in flutes (the curve pushed along its normal by
  a cos(gores·θ) wave whose amplitude makes its length the full circumference), one per
  gore, as a flared skirt hangs; the solver lets it settle into its folds.
* **Seams.** The right edge of gore k is sewn to the left edge of gore k+1, vertex to
  vertex (the rows match): a stiff zero-slack spring of rest length :data:`SEAM_GAP`
  per pair.  The seam vertices get a contact radius of SEAM_GAP / 2, so the cloth
  self-contact (radius + radius) and the stitch agree on their distance.  The render
  mesh fills each seam with a strip of two triangles per row.

All lengths in metres, world z up, the body's front towards −y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kesbrdf.cloth import mannequin as _mannequin
from kesbrdf.cloth.grid import ClothPiece, grid_piece

__all__ = ["SkirtPattern", "SEAM_GAP", "circumference", "gore_outline", "gored_skirt"]

#: Distance the stitches hold the two edges of a seam apart [m] (the stitch line).
SEAM_GAP = 0.002
#: Stiffness of the taped seams of a bias-cut gore, as a multiple of a plain stitch's
#: (E·t): with plain stitches the bias gore's seams opened to 4.4 mm during the turn at
#: resolution 16 (the tolerance is 4 mm, tests/cloth/test_garment.py).
BIAS_SEAM_FACTOR = 2.0
#: Clearance of the placed skirt from the body at the waist and at the hips [m].
WAIST_CLEARANCE = 0.005


@dataclass(frozen=True)
class SkirtPattern:
    """Measurements of the gored skirt [m].

    gores : number of panels (≥ 3).
    length : waist to hem along the grain line.
    hip_depth : waist to the hip line (fullest part of the body) along the grain.
    hip_ease : extra circumference at the hip line over the body's.
    hem_circumference : circumference of the hem (flare).
    hang_flare : fraction of the flare (girth beyond the hip's) kept in the mean girth of
        the placed skirt; the rest is laid in flutes, one per gore.
    bias_gores : gores cut on the bias (grain at 45°); gore 0 is the centre front.
    """

    gores: int = 6
    length: float = 0.62
    hip_depth: float = 0.22
    hip_ease: float = 0.06
    hem_circumference: float = 2.2
    hang_flare: float = 0.45
    bias_gores: tuple[int, ...] = (0,)


def _body_ellipse(z, grow=0.0):
    a, b, c = _mannequin.profile()(z)
    return a + grow, b + grow, c


def circumference(pattern: SkirtPattern, y) -> np.ndarray:
    """Skirt circumference C(y) [m] at depth y below the waist (flat-pattern widths).

    Drafted from the body as a pattern maker drafts from measurements: above the hip
    line the body's own girth at that height plus an ease growing smoothly from the
    waist clearance to ``hip_ease``; below it the flare, a straight line from the hip
    girth to the hem; the two joined by a smooth maximum (a 1 cm rounding), so the
    side seam has no kink.
    """
    y = np.asarray(y, float)
    zw, h = _mannequin.WAIST_Z, pattern.hip_depth
    body = _mannequin.ellipse_perimeter(*_body_ellipse(zw - np.minimum(y, h))[:2])
    e0 = float(_mannequin.ellipse_perimeter(*_body_ellipse(zw, WAIST_CLEARANCE)[:2])
               - _mannequin.ellipse_perimeter(*_body_ellipse(zw)[:2]))
    t = np.clip(y / h, 0.0, 1.0)
    fitted = body + e0 + (pattern.hip_ease - e0) * (3 * t**2 - 2 * t**3)
    ch = float(_mannequin.ellipse_perimeter(*_body_ellipse(zw - h)[:2])) + pattern.hip_ease
    flare = ch + (pattern.hem_circumference - ch) / (pattern.length - h) * (y - h)
    rounding = 0.01
    return 0.5 * (fitted + flare) + np.sqrt((0.5 * (fitted - flare)) ** 2 + rounding**2) - rounding


def gore_outline(pattern: SkirtPattern, rows: int, cols: int):
    """Pattern-space grid of one gore: ``(x, y)`` arrays of shape (rows+1, cols+1) [m]."""
    y = np.linspace(0.0, pattern.length, rows + 1)
    half = circumference(pattern, y) / (2 * pattern.gores)
    s = np.linspace(-1.0, 1.0, cols + 1)
    return s[None, :] * half[:, None], np.broadcast_to(y[:, None], (rows + 1, cols + 1)).copy()


def _grow_to_perimeter(a, b, target, iters: int = 48):
    """Growth d ≥ 0 with perimeter(a + d, b + d) = target (bisection, vectorised)."""
    lo = np.zeros_like(a)
    hi = np.maximum(target / (2 * np.pi), 0.0) + 0.0  # perimeter(a + d, b + d) > 2π d
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        big = _mannequin.ellipse_perimeter(a + mid, b + mid) > target
        hi = np.where(big, mid, hi)
        lo = np.where(big, lo, mid)
    return 0.5 * (lo + hi)


def _curve(a, b, c, amp, waves, t):
    """Points (rows, samples, 2) of fluted ellipses: the ellipse pushed along its normal by
    amp·cos(waves·(t + π/2)) (crests at the centre front and every 2π/waves)."""
    ct, st = np.cos(t)[None, :], np.sin(t)[None, :]
    px, py = a[:, None] * ct, c[:, None] + b[:, None] * st
    nx, ny = b[:, None] * ct, a[:, None] * st  # outward normal of the ellipse (unnormalised)
    norm = np.hypot(nx, ny)
    w = amp[:, None] * np.cos(waves * (t[None, :] + np.pi / 2))
    return np.stack([px + w * nx / norm, py + w * ny / norm], -1)


def _length(pts):
    return np.concatenate([np.zeros(pts.shape[:1] + (1,)),
                           np.cumsum(np.linalg.norm(np.diff(pts, axis=1), axis=-1), axis=1)], axis=1)


def _flute_amplitude(a, b, c, target, waves, t, iters: int = 40):
    """Amplitude with perimeter(fluted ellipse) = target (0 where the ellipse is long enough)."""
    lo, hi = np.zeros_like(a), np.maximum(a, b)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        long_ = _length(_curve(a, b, c, mid, waves, t))[:, -1] > target
        hi, lo = np.where(long_, mid, hi), np.where(long_, lo, mid)
    return np.where(target > _length(_curve(a, b, c, 0 * a, waves, t))[:, -1] + 1e-6, 0.5 * (lo + hi), 0.0)


def _arc_points(a, b, c, s_query, amp=None, waves: int = 6, samples: int = 4096):
    """Points at arc lengths ``s_query`` (rows, k) along the (fluted) row curves, from the front.

    Arc length runs counter-clockwise (seen from above) from the centre front, the
    point (0, c − b) at parameter angle −π/2.
    """
    t = -np.pi / 2 + np.linspace(0.0, 2 * np.pi, samples + 1)
    pts = _curve(a, b, c, np.zeros_like(a) if amp is None else amp, waves, t)
    cum = _length(pts)
    out = np.empty(s_query.shape + (2,))
    for r in range(len(a)):  # one interpolation per row (rows ≈ 30), vectorised along it
        sq = np.mod(s_query[r], cum[r, -1])
        out[r, :, 0] = np.interp(sq, cum[r], pts[r, :, 0])
        out[r, :, 1] = np.interp(sq, cum[r], pts[r, :, 1])
    return out


def gored_skirt(rows: int, cols: int, density: float, stretch: float, shear: float,
                pattern: SkirtPattern = SkirtPattern()):
    """The sewn skirt as one :class:`~kesbrdf.cloth.grid.ClothPiece` (z up, waist at 1 m).

    ``rows`` cells down each gore, ``cols`` across.  The waist row is pinned.  Extra
    fields on the piece: ``spring_rest`` (pattern rest lengths of the springs, seams
    included), ``flat_rest`` (bending rest angle 0), ``radius_scale`` (per-vertex
    contact radius factor: SEAM_GAP/2 over the default for seam vertices, as a length
    [m] in ``seam_radius``), ``seams`` (P, 2) stitched vertex pairs, ``panels``,
    ``bias_gores``.
    """
    n = pattern.gores
    bad = [g for g in pattern.bias_gores if not 0 <= int(g) < n]
    if bad:
        raise ValueError(f"pattern: expected bias gores in [0, {n - 1}], got {bad}")
    x, y = gore_outline(pattern, rows, cols)
    n_i, n_j = x.shape
    flat = np.stack([x, y, np.zeros_like(x)], -1)
    uv = np.stack([y, x + float(np.max(np.abs(x)))], -1)  # u down the grain line, v across
    straight = grid_piece(flat, uv, False, density, stretch, shear)
    r = np.sqrt(0.5)
    uv_bias = np.stack([r * (uv[..., 0] + uv[..., 1]), r * (uv[..., 1] - uv[..., 0])], -1)  # grain turned +45°
    bias = grid_piece(flat, uv_bias, False, density, stretch, shear, bias=True)

    # placement: rows on ellipses around the body, nearly isometric down the meridian;
    # below the hip line the flare is laid in flutes (one per gore, crest at its centre)
    # round an ellipse of the "hanging" girth, as a flared skirt falls
    yr = y[:, 0]
    circ = circumference(pattern, yr)
    perim = circ + n * SEAM_GAP
    h = pattern.hip_depth
    c_hip = float(circumference(pattern, h)) + n * SEAM_GAP
    hang = np.minimum(perim, c_hip + pattern.hang_flare * (perim - c_hip))
    radius = hang / (2 * np.pi)
    dz = np.sqrt(np.maximum(np.diff(yr) ** 2 - np.diff(radius) ** 2, 1e-12))
    z = _mannequin.WAIST_Z - np.concatenate([[0.0], np.cumsum(dz)])
    a0, b0, c0 = _body_ellipse(z)
    grow = _grow_to_perimeter(a0, b0, hang)
    A, B = a0 + grow, b0 + grow
    t = -np.pi / 2 + np.linspace(0.0, 2 * np.pi, 4097)
    amp = _flute_amplitude(A, B, c0, perim, n, t)

    n_per = n_i * n_j
    positions, faces, springs, ke, rest = [], [], [], [], []
    uvs = []
    for k in range(n):
        gore = bias if k in pattern.bias_gores else straight
        uvs.append(gore.uv_rest)
        s_query = k * perim[:, None] / n + x  # pattern x -> arc length on the row's ellipse
        xy = _arc_points(A, B, c0, s_query, amp, n)
        positions.append(np.concatenate([xy, np.broadcast_to(z[:, None, None], (n_i, n_j, 1))], -1).reshape(-1, 3))
        faces.append(gore.faces + k * n_per)
        springs.append(gore.springs + k * n_per)
        ke.append(gore.spring_ke)
        p = gore.positions.astype(np.float64)
        rest.append(np.linalg.norm(p[gore.springs[:, 0]] - p[gore.springs[:, 1]], axis=-1))
    idx = np.arange(n_per).reshape(n_i, n_j)
    right, left = idx[:, -1], idx[:, 0]
    seams = np.concatenate([np.stack([k * n_per + right, ((k + 1) % n) * n_per + left], -1) for k in range(n)])
    # a stitch is as stiff as the fabric across one cell (E·t); the seams of a bias-cut
    # gore are taped (stay-stitched), as a tailor tapes a bias edge so that it does not
    # stretch out: BIAS_SEAM_FACTOR × E·t
    seam_ke = np.full(len(seams), float(stretch))
    gore_of = seams // n_per
    on_bias = np.isin(gore_of[:, 0], pattern.bias_gores) | np.isin(gore_of[:, 1], pattern.bias_gores)
    seam_ke[on_bias] *= BIAS_SEAM_FACTOR
    springs.append(seams)
    ke.append(seam_ke)
    rest.append(np.full(len(seams), SEAM_GAP))

    N = n * n_per
    piece = ClothPiece(
        shape=(n_i, n_j), positions=np.concatenate(positions).astype(np.float32),
        faces=np.concatenate(faces).astype(np.int32), uv_rest=np.concatenate(uvs),
        masses=np.tile(straight.masses, n), springs=np.concatenate(springs).astype(np.int32),
        spring_ke=np.concatenate(ke), min_spring_length=float(np.min(np.concatenate(rest[:-1]))),
        pinned=np.zeros(N, bool), closed=False,
    )
    piece.pinned[np.concatenate([k * n_per + idx[0] for k in range(n)])] = True
    piece.spring_rest = np.concatenate(rest)
    piece.flat_rest = True
    piece.seams = seams.astype(np.int32)
    piece.seam_radius = SEAM_GAP / 2
    piece.panels = n
    piece.bias_gores = tuple(int(g) for g in pattern.bias_gores)
    # render mesh: the panels plus a two-triangle strip per row across every seam
    ri, li = seams[:, 0].reshape(n, n_i), seams[:, 1].reshape(n, n_i)
    a_, b_, c_, d_ = ri[:, :-1], ri[:, 1:], li[:, 1:], li[:, :-1]  # a: right edge row r, b: row r+1
    strip = np.concatenate([np.stack([a_, b_, c_], -1).reshape(-1, 3), np.stack([a_, c_, d_], -1).reshape(-1, 3)])
    piece.output_index = np.arange(N)
    piece.output_uv = piece.uv_rest.astype(np.float32)
    piece.output_faces = np.concatenate([piece.faces, strip]).astype(np.int32)
    piece.clearance = {"grow_min_m": float(grow.min()), "rows_z": z.tolist()}
    return piece
