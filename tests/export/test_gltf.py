"""glTF export: file structure, preview meshes, and the Khronos glTF-Validator as the real client."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from kesbrdf.export import glb, gltf
from kesbrdf.export.preview_mesh import swatch, uv_sphere

VIEWER = Path(__file__).resolve().parents[2] / "viewer"
VALIDATE = VIEWER / "scripts" / "gltf-validate.mjs"
#: float32 attributes: unit length to 1e-6 (the validator's own tolerance is 4e-4)
UNIT_TOL = 1e-6


@pytest.mark.parametrize("mesh", [swatch(1.0, 3), uv_sphere(0.5, 8, 16)], ids=lambda m: m.name)
def test_preview_mesh_tangent_frame(mesh):
    """Unit NORMAL and TANGENT, orthogonal, w = +1, and counter-clockwise outward triangles."""
    n, t = mesh.normals.astype(float), mesh.tangents.astype(float)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=UNIT_TOL)
    np.testing.assert_allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=UNIT_TOL)
    np.testing.assert_allclose(np.sum(n * t[:, :3], axis=1), 0, atol=UNIT_TOL)
    assert np.all(t[:, 3] == 1.0)
    tri = mesh.indices.reshape(-1, 3)
    p = mesh.positions.astype(float)
    face_n = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    assert np.all(np.linalg.norm(face_n, axis=1) > 0), "degenerate triangle"
    assert np.all(np.sum(face_n * n[tri].mean(axis=1), axis=1) > 0), "triangle faces inward"


def test_gltf_material_carries_fit_and_extensions(tmp_path, kes_model, fits):
    res = gltf.export(kes_model, tmp_path / "f.gltf", fit=fits["gltf_pbr"])
    doc = json.loads((tmp_path / "f.gltf").read_text())
    assert res["size"] == (tmp_path / "f.gltf").stat().st_size
    assert set(doc["extensionsUsed"]) == {"KHR_materials_anisotropy", "KHR_materials_sheen", "KHR_materials_specular"}
    mat = doc["materials"][0]
    ext = mat["extensions"]
    assert ext["KHR_materials_anisotropy"]["anisotropyRotation"] == pytest.approx(fits["gltf_pbr"].params["anisotropy_rotation"])
    assert mat["extras"]["kesbrdf"]["fit_error"]["nrmse"] == pytest.approx(fits["gltf_pbr"].error["nrmse"])
    assert "APPROXIMATION" in mat["extras"]["kesbrdf"]["note"]
    for m in doc["meshes"]:
        assert {"POSITION", "NORMAL", "TANGENT", "TEXCOORD_0"} <= set(m["primitives"][0]["attributes"])


def test_glb_round_trips_through_pygltflib(tmp_path, kes_model, fits):
    import pygltflib

    glb.export(kes_model, tmp_path / "f.glb", fit=fits["gltf_pbr"])
    g = pygltflib.GLTF2().load_binary(str(tmp_path / "f.glb"))
    assert g.materials[0].extensions["KHR_materials_sheen"]["sheenRoughnessFactor"] == pytest.approx(
        fits["gltf_pbr"].params["sheen_roughness"]
    )
    assert len(g.binary_blob()) == g.buffers[0].byteLength


def test_gltf_rejects_unknown_suffix(tmp_path, kes_model, fits):
    from kesbrdf.errors import KesbrdfError

    with pytest.raises(KesbrdfError, match=r"\.gltf or \.glb"):
        gltf.export(kes_model, tmp_path / "f.obj", fit=fits["gltf_pbr"])


def test_khronos_gltf_validator_reports_no_errors_or_warnings(tmp_path, kes_model, fits):
    """The Khronos glTF-Validator (npm gltf-validator) is the real client check."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (CI has it): the Khronos glTF-Validator runs on node")
    if not (VIEWER / "node_modules" / "gltf-validator").is_dir():
        pytest.fail("viewer/node_modules/gltf-validator is missing: run `make viewer` (npm ci in viewer/)")
    files = [tmp_path / "f.gltf", tmp_path / "f.glb"]
    gltf.export(kes_model, files[0], fit=fits["gltf_pbr"])
    glb.export(kes_model, files[1], fit=fits["gltf_pbr"])
    proc = subprocess.run([node, str(VALIDATE), *map(str, files)], cwd=VIEWER, capture_output=True, text=True, timeout=120)
    reports = [json.loads(line) for line in proc.stdout.splitlines()]
    assert len(reports) == 2, proc.stderr
    for r in reports:
        issues = r["report"]["issues"]
        assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), issues["messages"]
        # infos only: the validator does not know that KHR_materials_anisotropy uses TANGENT
        assert {m["code"] for m in issues["messages"]} <= {"UNUSED_MESH_TANGENT", "UNUSED_OBJECT"}
        assert r["report"]["info"]["materialCount"] == 1
