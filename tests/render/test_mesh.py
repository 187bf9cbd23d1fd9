"""Procedural meshes and the PLY writer: UVs carry the warp, Mitsuba reads them back."""

import numpy as np
import pytest

from kesbrdf.io.ply import write_ply
from kesbrdf.render import mesh


def test_rotate_uv_quarter_turn_maps_u_to_v():
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.5], [0.25, 0.75]])
    r = mesh.rotate_uv(uv, 90)
    # a quarter turn about the centre: u' = 1 - v, v' = u
    np.testing.assert_allclose(r, np.stack([1 - uv[:, 1], uv[:, 0]], -1))
    np.testing.assert_allclose(mesh.rotate_uv(uv, 360), uv)


def test_swatch_u_runs_along_x_and_uv_frame_is_right_handed():
    p, n, uv, f = mesh.swatch(n=5)
    du = p[uv[:, 0] == 1].mean(0) - p[uv[:, 0] == 0].mean(0)
    dv = p[uv[:, 1] == 1].mean(0) - p[uv[:, 1] == 0].mean(0)
    np.testing.assert_allclose(du, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(n, np.tile([0.0, 1.0, 0.0], (len(n), 1)), atol=1e-12)
    # normal = du x dv: Mitsuba's t = n x s is then +v (the weft)
    np.testing.assert_allclose(np.cross(du, dv), [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("make", [mesh.folded_cloth, mesh.skirt, mesh.ellipsoid])
def test_vertex_normals_agree_with_uv_orientation(make):
    p, n, uv, f = make()
    face_n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    ok = np.linalg.norm(face_n, axis=1) > 1e-12
    agree = np.sum(face_n[ok] * n[f[ok, 0]], axis=1) > 0
    assert agree.mean() > 0.99


def test_skirt_warp_runs_from_waist_to_hem():
    p, _, uv, _ = mesh.skirt(n_u=6, n_v=13)
    top = p[uv[:, 0] == 0][:, 1].mean()
    hem = p[uv[:, 0] == 1][:, 1].mean()
    assert top > hem


@pytest.mark.render
def test_ply_round_trip_through_mitsuba(render_module, tmp_path):
    import mitsuba as mi

    p, n, uv, f = mesh.folded_cloth(n=9)
    write_ply(tmp_path / "c.ply", p, f, n, uv)
    shape = mi.load_dict({"type": "ply", "filename": str(tmp_path / "c.ply")})
    params = mi.traverse(shape)
    np.testing.assert_allclose(np.array(params["vertex_positions"]).reshape(-1, 3), p, atol=1e-6)
    np.testing.assert_allclose(np.array(params["vertex_texcoords"]).reshape(-1, 2), uv, atol=1e-6)
    assert np.array(params["faces"]).reshape(-1, 3).tolist() == f.tolist()
