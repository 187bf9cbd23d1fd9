"""kesbrdf.cloth.drape: the newton XPBD drape (falls, rests, no penetration, resumes)."""

import json

import numpy as np
import pytest

from kesbrdf.cloth import scenes
from kesbrdf.cloth.drape import (CHECKPOINT, DrapeError, DrapeParameters, build_scene, frame_name,
                                 load_checkpoint, simulate_drape, substeps_for)
from kesbrdf.cloth.ply import read_ply

pytest.importorskip("newton")
pytest.importorskip("warp")

#: Deepest a cloth vertex may sit inside a collider [m]: contacts keep vertices a
#: particle radius (3 mm) outside; 1 mm inside would be a visible intersection.
PENETRATION_TOL = 1e-3
#: Mean vertex speed [m/s] below which the sheet counts as at rest; it hits the
#: sphere at about sqrt(2 g 0.15 m) = 1.7 m/s, so this is ~6 % of the impact speed.
REST_MEAN_SPEED = 0.1
#: Largest spring strain of the sheet at rest: E t = 40 N/m under a 1 m sheet's own weight
#: gives a few percent (4 % measured at resolution 48); 8 % would mean the XPBD solve
#: is too soft or not converging.
MAX_REST_STRAIN = 0.08
#: Resumption is exact on Warp's serial CPU backend: no tolerance.
RESUME_TOL = 0.0

SPHERE = scenes.sphere_scene(16, 0.12, 40.0, 0.1).colliders[0]


@pytest.fixture(scope="module")
def sphere_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sphere")
    simulate_drape("sphere", out, 60, resolution=16, seed=3)
    return out


@pytest.mark.cloth
def test_frames_finite_and_manifest_complete(sphere_run):
    meta = json.loads((sphere_run / "drape.json").read_text())
    assert meta["format"] == "kesbrdf-drape" and meta["version"] == 1 and meta["complete"]
    assert meta["frames"] == [frame_name(k) for k in range(60)]
    assert meta["colliders"][0]["file"] == "collider_0.ply" and meta["colliders"][0]["kind"] == "sphere"
    assert meta["parameters"]["resolution"] == 16 and meta["up_axis"] == "z"
    for name in meta["frames"]:
        m = read_ply(sphere_run / name)
        assert np.isfinite(m.vertices).all() and np.isfinite(m.normals).all()
    assert (sphere_run / "collider_0.ply").is_file()


@pytest.mark.cloth
def test_sheet_falls_and_rests_on_the_sphere(sphere_run):
    z0 = read_ply(sphere_run / frame_name(0)).vertices[:, 2].mean()
    last = read_ply(sphere_run / frame_name(59)).vertices
    assert last[:, 2].mean() < z0 - 0.3  # the centre of mass went down
    # the top of the sheet lies on the sphere's top (2R = 0.6 m) plus the contact radius
    assert 0.6 <= last[:, 2].max() <= 0.6 + 2 * 0.003
    speed = np.linalg.norm(load_checkpoint(sphere_run)["qd"], axis=1)
    assert speed.mean() < REST_MEAN_SPEED


@pytest.mark.cloth
def test_stretch_at_rest_is_small(sphere_run):
    rest = read_ply(sphere_run / frame_name(0)).vertices.reshape(17, 17, 3)
    last = read_ply(sphere_run / frame_name(59)).vertices.reshape(17, 17, 3)
    for axis in (0, 1):  # warp, weft
        strain = np.linalg.norm(np.diff(last, axis=axis), axis=-1) / np.linalg.norm(np.diff(rest, axis=axis), axis=-1) - 1
        assert strain.max() < MAX_REST_STRAIN


@pytest.mark.cloth
def test_no_penetration_of_sphere_or_floor(sphere_run):
    for k in range(60):
        p = read_ply(sphere_run / frame_name(k)).vertices
        assert scenes.signed_distance(SPHERE, p).min() > -PENETRATION_TOL
        assert p[:, 2].min() > -PENETRATION_TOL


@pytest.mark.cloth
def test_uv_u_runs_along_the_warp(sphere_run):
    m = read_ply(sphere_run / frame_name(0))
    # frame 0 is the flat sheet (plus <= 0.2 mm jitter, <= 2 cm offset): u follows world x
    du = m.uv[:, 0] - m.uv[:, 0].mean()
    dx = m.vertices[:, 0] - m.vertices[:, 0].mean()
    np.testing.assert_allclose(du, dx, atol=1e-4)
    assert m.uv[:, 0].max() == pytest.approx(1.0) and m.uv[:, 1].max() == pytest.approx(1.0)


@pytest.mark.cloth
def test_resume_after_interruption_matches_uninterrupted(tmp_path):
    full = simulate_drape("sphere", tmp_path / "full", 16, resolution=10)

    class Stop(Exception):
        pass

    def interrupt(done, total):
        if done == 7:
            raise Stop

    with pytest.raises(Stop):
        simulate_drape("sphere", tmp_path / "cut", 16, resolution=10, progress=interrupt)
    assert load_checkpoint(tmp_path / "cut")["frame"] == 6
    assert not (tmp_path / "cut" / frame_name(7)).exists()
    meta = json.loads((tmp_path / "cut" / "drape.json").read_text())
    assert meta["complete"] is False and len(meta["frames"]) == 7
    seen = []
    simulate_drape("sphere", tmp_path / "cut", 16, resolution=10, progress=lambda d, t: seen.append(d))
    assert seen[0] == 7  # resumed after the last finished frame, not from scratch
    for k in range(16):
        a = read_ply(full / frame_name(k)).vertices
        b = read_ply(tmp_path / "cut" / frame_name(k)).vertices
        np.testing.assert_allclose(b, a, rtol=0, atol=RESUME_TOL)


@pytest.mark.cloth
def test_other_parameters_in_folder_refused_unless_overwrite(tmp_path):
    simulate_drape("sphere", tmp_path, 2, resolution=6)
    with pytest.raises(DrapeError, match="different parameters"):
        simulate_drape("sphere", tmp_path, 2, resolution=6, seed=1)
    simulate_drape("sphere", tmp_path, 2, resolution=6, seed=1, overwrite=True)
    assert json.loads((tmp_path / "drape.json").read_text())["parameters"]["seed"] == 1
    assert (tmp_path / CHECKPOINT).is_file()


@pytest.mark.cloth
def test_dressform_skirt_pinned_and_outside_the_form(tmp_path):
    out = simulate_drape("dressform", tmp_path, 8, resolution=8)
    meta = json.loads((out / "drape.json").read_text())
    assert [c["kind"] for c in meta["colliders"]].count("capsule") == 6
    first = read_ply(out / frame_name(0)).vertices
    last = read_ply(out / frame_name(7)).vertices
    assert np.isfinite(last).all()
    waist = np.isclose(first[:, 2], 1.0)
    np.testing.assert_array_equal(last[waist], first[waist])  # pinned waist does not move
    assert last[~waist, 2].mean() < first[~waist, 2].mean()  # the rest hangs down
    for c in scenes.DRESS_FORM:
        assert scenes.signed_distance(c, last).min() > -PENETRATION_TOL


@pytest.mark.parametrize("kw, match", [
    (dict(scene="cube"), "scene"),
    (dict(fps=0.0), "fps"),
    (dict(resolution=2), "resolution"),
    (dict(density_kg_m2=5.0), "density"),
    (dict(seed=-1), "seed"),
    (dict(self_contact="yes"), "self_contact"),
])
def test_parameter_validation(kw, match):
    with pytest.raises(DrapeError, match=match):
        DrapeParameters(**kw).validate()


def test_bad_frames_and_unknown_parameter(tmp_path):
    with pytest.raises(DrapeError, match="frames"):
        simulate_drape("sphere", tmp_path, 0)
    with pytest.raises(DrapeError, match="unknown parameter"):
        simulate_drape("sphere", tmp_path, 2, stiffness=3)


def test_substeps_follow_the_stability_bound():
    # k dt^2 / m is scale-free: halving the cell (m / 4, k same) doubles the substeps
    n16, dt16 = substeps_for(build_scene(DrapeParameters(resolution=16)).cloth, 30.0)
    n32, dt32 = substeps_for(build_scene(DrapeParameters(resolution=32)).cloth, 30.0)
    assert dt16 / dt32 == pytest.approx(2.0, rel=1e-6)
    with pytest.raises(DrapeError, match="substeps"):
        substeps_for(build_scene(DrapeParameters(resolution=64, stretch_stiffness_n_m=2000,
                                                 density_kg_m2=0.02)).cloth, 1.0)
