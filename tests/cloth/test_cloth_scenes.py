"""kesbrdf.cloth.scenes: cloth grids (UVs along the warp), colliders, distances."""

import numpy as np
import pytest

from kesbrdf.cloth import scenes
from kesbrdf.cloth.ply import vertex_normals

#: float32 vertex positions of ~1 m meshes: a few ulps.
GEOM_TOL = 1e-5


def _uv_signed_areas(uv, faces):
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])


def test_sheet_u_runs_along_warp_in_metres():
    piece = scenes.sheet(8, size=1.0, height=0.5, density=0.12, stretch=40, shear=0.1)
    p = piece.positions[piece.output_index]
    uv = piece.output_uv
    # u = x + 0.5 (warp along world x, metres), v = y + 0.5
    np.testing.assert_allclose(uv[:, 0], p[:, 0] + 0.5, atol=GEOM_TOL)
    np.testing.assert_allclose(uv[:, 1], p[:, 1] + 0.5, atol=GEOM_TOL)
    # first grid axis is the warp: row i has constant u
    grid_u = uv[:, 0].reshape(9, 9)
    assert np.all(np.diff(grid_u, axis=0) > 0) and np.allclose(np.diff(grid_u, axis=1), 0)


def test_faces_wound_so_du_cross_dv_is_the_normal():
    for piece in (scenes.sheet(6, 1.0, 0.5, 0.12, 40, 0.1),
                  scenes.skirt(4, 12, 1.0, 0.14, 0.4, 0.5, 0.12, 40, 0.1)):
        assert np.all(_uv_signed_areas(piece.output_uv, piece.output_faces) > 0)


def test_skirt_normals_point_outward_and_seam_is_duplicated():
    piece = scenes.skirt(4, 12, waist_z=1.0, waist_radius=0.14, hem_radius=0.4, length=0.5,
                         density=0.12, stretch=40, shear=0.1)
    p = piece.positions[piece.output_index]
    assert len(p) == 5 * 13
    n = vertex_normals(piece.positions, piece.faces)[piece.output_index]
    radial = p[:, :2] / np.linalg.norm(p[:, :2], axis=1, keepdims=True)
    assert np.all(np.sum(n[:, :2] * radial, axis=1) > 0)
    uv = piece.output_uv.reshape(5, 13, 2)
    r = np.linalg.norm(p[:, :2], axis=1).reshape(5, 13)
    # the duplicated seam column closes the circle: v = 2 pi r there
    np.testing.assert_allclose(uv[:, -1, 1], 2 * np.pi * r[:, 0], rtol=GEOM_TOL)
    assert piece.pinned.sum() == 12 and np.all(piece.positions[piece.pinned, 2] == pytest.approx(1.0))


def test_lumped_mass_equals_density_times_area():
    piece = scenes.sheet(10, size=1.0, height=0.5, density=0.12, stretch=40, shear=0.1)
    assert piece.masses.sum() == pytest.approx(0.12 * 1.0 * 1.0)
    # interior square-cell warp spring carries the sheet stiffness E t
    interior = np.isclose(piece.spring_ke, 40.0)
    assert interior.sum() == 2 * 9 * 10  # interior axis-aligned edges


@pytest.mark.parametrize("collider", [scenes.Collider("sphere", (0.1, 0.2, 0.3), radius=0.3)]
                         + list(scenes.DRESS_FORM), ids=lambda c: c.label or c.kind)
def test_collider_meshes_lie_on_the_surface(collider):
    p, n, uv, f = scenes.collider_mesh(collider)
    assert np.abs(scenes.signed_distance(collider, p)).max() < GEOM_TOL
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=GEOM_TOL)
    # normals point out: a step along them leaves the solid
    assert np.all(scenes.signed_distance(collider, p + 1e-3 * n) > 0)
    assert f.min() >= 0 and f.max() < len(p) and uv.shape == (len(p), 2)


def test_signed_distance_known_values():
    cap = scenes.Collider("capsule", (0, 0, 0), 0.1, (1, 0, 0), 0.2)
    assert scenes.signed_distance(cap, [0.0, 0.3, 0.0]) == pytest.approx(0.2)
    assert scenes.signed_distance(cap, [0.5, 0.0, 0.0]) == pytest.approx(0.2)
    box = scenes.Collider("box", (0, 0, 0), half_extents=(1, 1, 1))
    assert scenes.signed_distance(box, [0.0, 0.0, 0.5]) == pytest.approx(-0.5)
