"""The Mitsuba 3 scene export: both XML scenes load with mi.load_file and render the same fabric."""

import importlib.util

import numpy as np
import pytest

pytestmark = [
    pytest.mark.render,
    pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="needs mitsuba (kesbrdf[render])"),
]

#: Mean image brightness of the two scenes (path tracing, 32×24 at 32 spp, different
#: sampling strategies, so noisy): they agree within this (measured: 0.15 %; 160×120: 0.05 %).
MEAN_REL_BOUND = 0.05


@pytest.fixture(scope="module")
def scene_files(tmp_path_factory):
    from kesbrdf.export import export
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    model = fit(measure(AnisotropicWard(0.1, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.1)))
    out = tmp_path_factory.mktemp("scene") / "fabric.xml"
    result = export(model, "mitsuba-scene", out, n_theta_i=9, n_phi_i=17, n=24, n_ndf=32, check=False)
    return out, result


def test_files_written_side_by_side(scene_files):
    out, result = scene_files
    names = sorted(p.name for p in result.paths)
    assert names == ["fabric.bsdf", "fabric.kes.json", "fabric.xml", "fabric_measured.xml"]
    assert result.size == sum(p.stat().st_size for p in result.paths)
    assert 'type="measured"' in (out.parent / "fabric_measured.xml").read_text()
    assert 'value="fabric.kes.json"' in out.read_text()  # relative: the folder can move


def test_both_scenes_load_and_render_alike(scene_files, tmp_path, monkeypatch):
    import kesbrdf.render  # noqa: F401  (registers the kesbrdf plugin)
    from kesbrdf._drjit import import_mitsuba

    mi, dr = import_mitsuba("test")
    out, _ = scene_files
    monkeypatch.chdir(tmp_path)  # filenames must resolve from the scene's folder, not the cwd
    images = []
    for name in ("fabric.xml", "fabric_measured.xml"):
        scene = mi.load_file(str(out.parent / name), spp=32, width=32, height=24)
        img = np.array(mi.render(scene, seed=1), float)[..., :3]
        assert img.shape == (24, 32, 3) and np.all(np.isfinite(img)) and img.mean() > 0.01
        images.append(img)
    assert images[1].mean() == pytest.approx(images[0].mean(), rel=MEAN_REL_BOUND)


def test_unknown_option_fails_before_writing(tmp_path):
    from kesbrdf.errors import ExportError
    from kesbrdf.export import export
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    model = fit(measure(AnisotropicWard(0.2, 0.2)))
    with pytest.raises(ExportError, match="unknown option"):
        export(model, "mitsuba-scene", tmp_path / "x.xml", n_thetas=3)
    assert list(tmp_path.iterdir()) == []


def test_other_kinds_get_the_measured_scene(tmp_path):
    from kesbrdf._drjit import import_mitsuba
    from kesbrdf.export import export
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.halfdiff import fit_halfdiff
    from kesbrdf.references.ward import AnisotropicWard

    mi, _ = import_mitsuba("test")
    model = fit_halfdiff(measure(AnisotropicWard(0.1, 0.3, rho_d=0.2, rho_s=0.1), protocol="dense", step_deg=10))
    result = export(model, "mitsuba-scene", tmp_path / "hd.xml", n_theta_i=5, n_phi_i=9, n=16, n_ndf=16)
    assert sorted(p.name for p in result.paths) == ["hd.bsdf", "hd.xml"]
    assert 'type="measured"' in (tmp_path / "hd.xml").read_text()
    img = np.array(mi.render(mi.load_file(str(tmp_path / "hd.xml"), spp=4, width=16, height=12)), float)
    assert np.all(np.isfinite(img)) and img.mean() > 0.01


def test_measured_scene_renders_in_the_mitsuba_command_line(scene_files, tmp_path):
    """The ``measured`` scene needs no Python: Mitsuba's own executable renders it."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).with_name("mitsuba")
    exe = str(exe) if exe.exists() else shutil.which("mitsuba")
    if exe is None:
        pytest.skip("no mitsuba executable")
    out, _ = scene_files
    img = tmp_path / "cli.exr"
    env = dict(os.environ)
    from kesbrdf._drjit import LLVM_CANDIDATES

    env.setdefault("DRJIT_LIBLLVM_PATH", next((c for c in LLVM_CANDIDATES if Path(c).exists()), ""))
    run = subprocess.run([exe, "-m", "scalar_rgb", "-Dspp=2", "-Dwidth=16", "-Dheight=12", "-o", str(img),
                          str(out.parent / "fabric_measured.xml")], capture_output=True, text=True, env=env,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert img.is_file() and img.stat().st_size > 0


def test_the_measured_scene_reuses_the_rgl_tensor_built_in_this_process(tmp_path, monkeypatch):
    """``kesbrdf demo`` exports rgl-bsdf, then mitsuba-scene: the second must not rebuild the
    tensor (15 s of the demo), and must write the same bytes; another model rebuilds."""
    from kesbrdf.export import export, rgl_bsdf
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    calls = []
    real = rgl_bsdf.build_fields
    monkeypatch.setattr(rgl_bsdf, "build_fields", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(rgl_bsdf, "_FIELDS_MEMO", {})
    small = dict(n_theta_i=5, n_phi_i=9, n=12, n_ndf=16, check=False)
    model = fit(measure(AnisotropicWard(0.1, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.1)))
    export(model, "rgl-bsdf", tmp_path / "a.bsdf", **small)
    export(model, "mitsuba-scene", tmp_path / "s" / "fabric.xml", **small)
    assert len(calls) == 1
    assert (tmp_path / "a.bsdf").read_bytes() == (tmp_path / "s" / "fabric.bsdf").read_bytes()
    other = fit(measure(AnisotropicWard(0.2, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.1)))
    export(other, "rgl-bsdf", tmp_path / "b.bsdf", **small)
    assert len(calls) == 2
