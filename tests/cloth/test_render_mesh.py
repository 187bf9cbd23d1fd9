"""The garment's render mesh: seams welded, Loop subdivision, smooth normals (cloth.render_mesh)."""

import numpy as np
import pytest

from kesbrdf.cloth import scenes
from kesbrdf.cloth.render_mesh import SmoothMesh, loop_step


def _face_normals(p, f):
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _edge_neighbours(f):
    """(a, b): the two faces of every edge that two faces share."""
    half = np.stack([f, np.roll(f, -1, axis=1)], -1).reshape(-1, 2)
    key = np.sort(half, axis=1)
    face = np.repeat(np.arange(len(f)), 3)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, face = key[order], face[order]
    same = (key[1:] == key[:-1]).all(axis=1)
    return face[1:][same], face[:-1][same]


def _turn_deg(v, f):
    """Angle between the unit per-face vectors ``v`` of each pair of neighbouring faces."""
    a, b = _edge_neighbours(f)
    return np.degrees(np.arccos(np.clip(np.sum(v[a] * v[b], axis=1), -1, 1)))


def _largest_crease_deg(p, f):
    """Largest angle between the normals of two faces sharing an edge (a facet edge)."""
    return float(_turn_deg(_face_normals(p, f), f).max())


@pytest.fixture(scope="module")
def garment():
    return scenes.garment_scene(48, 0.12, 40.0, 0.1).cloth


def test_loop_rows_are_affine_combinations():
    # a closed octahedron: every new point is a weighted mean (rows sum to 1, weights ≥ 0)
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    S, new_faces, edges = loop_step(6, f)
    assert S.shape == (6 + 12, 6) and len(new_faces) == 32 and len(edges) == 12
    assert np.allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert S.min() >= 0.0


def test_seams_are_welded_and_panels_keep_their_grain(garment):
    sm = SmoothMesh(garment.output_faces, garment.output_uv, garment.seams, levels=1)
    p, n = sm.apply(garment.positions)
    s = garment.seams
    # the stitched pair sits at one point, with one normal (no crease, no slit)
    assert np.array_equal(p[s[:, 0]], p[s[:, 1]]) and np.array_equal(n[s[:, 0]], n[s[:, 1]])
    # ... but each side keeps its own panel's grain-line UV: Loop's boundary rule on the
    # panel moves a seam vertex's UV by at most 1/8 of its two boundary edges (a panel
    # corner at the hem: 5.5 mm measured), never across to the other panel's (the two
    # sides of a straight-grain seam are a panel width, > 5 cm, apart in v)
    for side in (0, 1):
        assert np.abs(sm.uv[s[:, side]] - garment.output_uv[s[:, side]]).max() < 0.006
    straight = (s[:, 0] // (len(garment.positions) // 6) != 0) & (s[:, 1] // (len(garment.positions) // 6) != 0)
    assert (np.abs(sm.uv[s[straight, 0], 1] - sm.uv[s[straight, 1], 1]) > 0.05).all()
    # every triangle still faces out (no flipped faces): its normal agrees with the vertex normals
    fn = _face_normals(p.astype(float), sm.faces)
    vn = n[sm.faces].mean(axis=1)
    assert (np.sum(fn * vn, axis=1) > 0.5).all()
    # one level quadruples the faces (the seam strips, 2 a row a seam, are gone)
    panel_faces = len(garment.output_faces) - 2 * (garment.shape[0] - 1) * 6
    assert len(sm.faces) == 4 * panel_faces


def test_subdivision_takes_the_facets_off(garment):
    """The placed skirt is fluted round the body: its coarse mesh creases by tens of
    degrees between neighbouring faces (70° measured at resolution 48).  On a smooth
    surface the angle between neighbouring faces is proportional to their size, so each
    Loop level, which halves the edges, should about halve the largest crease: measured
    0.56× and 0.57× (the waist and hem boundaries and the valence-4/8 vertices of the
    alternating diagonals converge a little slower); the bound is 0.6× a level, which a
    mesh split without smoothing (1×) fails."""
    sm0 = SmoothMesh(garment.output_faces, garment.output_uv, garment.seams, levels=0)
    q = garment.positions.astype(float)
    c0 = _largest_crease_deg(sm0.matrix @ q, sm0.welded_faces)  # welded: the seams count too
    c = []
    for levels in (1, 2):
        sm = SmoothMesh(garment.output_faces, garment.output_uv, garment.seams, levels=levels)
        c.append(_largest_crease_deg(sm.matrix @ q, sm.welded_faces))
    assert c[0] < 0.6 * c0 and c[1] < 0.6 * c[0], (c0, c)
    # subdivision does not shrink the skirt into the body: vertices move < 2 mm
    sm = SmoothMesh(garment.output_faces, garment.output_uv, garment.seams, levels=1)
    p, _ = sm.apply(garment.positions)
    assert np.abs(p[: len(garment.positions)] - garment.positions).max() < 0.03


def _dpdu(p, uv, f):
    d_uv = np.stack([uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]], 1).astype(float)
    d_p = np.stack([p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]], 1).astype(float)
    t = np.einsum("fij,fjk->fik", np.linalg.inv(d_uv), d_p)[:, 0]
    return t / np.linalg.norm(t, axis=1, keepdims=True)


def test_the_warp_direction_does_not_quilt(garment):
    """Mitsuba takes the BSDF's warp from ∂p/∂u, constant per triangle.  With UVs split
    linearly under Loop-moved positions it swings between neighbouring triangles in a
    pattern of the simulation grid (a quilted diamond pattern in the satin highlight,
    seen at 640×360); with Loop's weights on the UVs too it turns smoothly: the 99th
    percentile of the turn between neighbouring triangles must at least halve (measured
    at resolution 48: 27° linear, 8.7° with Loop UVs; medians 6.5° and 0.6°)."""
    q = garment.positions
    turns = {}
    for smooth in (False, True):
        sm = SmoothMesh(garment.output_faces, garment.output_uv, garment.seams, levels=1, smooth_uv=smooth)
        p, _ = sm.apply(q)
        turns[smooth] = float(np.percentile(_turn_deg(_dpdu(p, sm.uv, sm.faces), sm.faces), 99))
    assert turns[True] < 0.5 * turns[False], turns
