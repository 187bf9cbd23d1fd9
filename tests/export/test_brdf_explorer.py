"""BRDF Explorer export: glslangValidator compiles it, and its GLSL evaluates the model.

The agreement is checked in two steps that together cover the file:
1. the GLSL ``BRDF`` function, run in headless Chromium (WebGL2), equals its numpy port
   (:func:`kesbrdf.export.brdf_explorer.numpy_port`) to float32 rounding, on a small
   baked table (SwiftShader compiles large constant arrays slowly);
2. the numpy port on the full-resolution table equals :func:`kesbrdf.models.brdf.evaluate`
   to float64 rounding, and the default downsampled table's error is bounded.
Both for a current model file (bounded foreshortening, fading lobe) and a file written
before those parameters existed (√(cos θ_i cos θ_r), last column held; docs/formats.md).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from kesbrdf.models.brdf import evaluate
from kesbrdf.errors import KesbrdfError
from kesbrdf.export import brdf_explorer as be

VIEWER = Path(__file__).resolve().parents[2] / "viewer"
#: float32 shading against the float64 port (f_r spans ~1e-3..1e2; 1e-4 relative is
#: ~1000 float32 ulps, far below any mapping or lookup bug, which gives O(1) errors)
GLSL_REL_TOL = 1e-4
#: float64 port against float64 kesbrdf.models.brdf.evaluate (same recipe, same table)
PORT_REL_TOL = 1e-9
#: default 90-φ table against the full model, measured on the test fabric (Ward):
#: p90 0.09 %, max 1 %; bounds with margin
DOWNSAMPLE_P90_TOL = 0.005
DOWNSAMPLE_MAX_TOL = 0.05


@pytest.fixture(scope="module")
def law_model():
    """A table over a Fresnel-like body (GGX reference; eq. B3 of kesbrdf.models.body)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ggx import AnisotropicGGX

    model = fit(measure(AnisotropicGGX(0.15, 0.3, eta=1.5, rho_d=[0.5, 0.3, 0.2], k_s=0.6)))
    assert model.body_law is not None
    return model


@pytest.fixture(params=["current", "legacy", "body-law"])
def any_model(request, kes_model, law_model):
    """The test fabric as fitted now, as a file without ``normalisation`` /
    ``extrapolation`` reads (the same table, evaluated the old way), and a table over a
    Fresnel-like body."""
    if request.param == "current":
        assert (kes_model.normalisation, kes_model.extrapolation) == ("bounded", "fade")
        return kes_model
    if request.param == "body-law":
        return law_model
    params = {k: v for k, v in kes_model.parameters.items() if k not in ("normalisation", "extrapolation")}
    legacy = dataclasses.replace(kes_model, parameters=params)
    assert (legacy.normalisation, legacy.extrapolation) == ("sqrtcos", "hold")
    return legacy


def _pairs(rng, n, max_theta_deg=80.0):
    def dirs():
        mu = rng.uniform(np.cos(np.radians(max_theta_deg)), 1, n)
        ph = rng.uniform(0, 2 * np.pi, n)
        s = np.sqrt(1 - mu**2)
        return np.stack([s * np.cos(ph), s * np.sin(ph), mu], -1)

    return dirs(), dirs()


def _shader(text):
    return text.split("::begin shader", 1)[1].split("::end shader", 1)[0]


def test_file_layout(tmp_path, kes_model):
    res = be.export(kes_model, tmp_path / "fabric.brdf")
    text = (tmp_path / "fabric.brdf").read_text()
    assert text.startswith("analytic\n")
    for section in ("::begin parameters", "::end parameters", "::begin shader", "::end shader"):
        assert text.count(section) == 1
    params = text.split("::begin parameters")[1].split("::end parameters")[0].split("\n")
    # the shader's default mapping is the model's own (conftest's model: deviation)
    flag = 1 if kes_model.default_mapping == "halfvector" else 0
    assert "float scale 0 4 1" in params and f"bool halfvector {flag}" in params and "color tint 1 1 1" in params
    assert "vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)" in text
    assert res.agreement["table"]["entries_per_channel"] <= be.MAX_TABLE_ENTRIES
    assert res.size == (tmp_path / "fabric.brdf").stat().st_size


def test_glslang_compiles_with_brdf_explorer_header(tmp_path, kes_model):
    exe = shutil.which("glslangValidator")
    if exe is None:
        pytest.skip("glslangValidator is not installed (Debian glslang-tools, scripts/setup-system.sh)")
    text, _ = be.brdf_explorer_source(kes_model)
    good = tmp_path / "brdf.frag"
    good.write_text(be.BRDF_EXPLORER_HEADER + _shader(text) + be.BRDF_EXPLORER_MAIN)
    proc = subprocess.run([exe, str(good)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # the check can fail: the same shader without BRDF Explorer's parameter uniforms
    bad = tmp_path / "bad.frag"
    bad.write_text(be.BRDF_EXPLORER_HEADER.replace("uniform bool halfvector;\n", "") + _shader(text) + be.BRDF_EXPLORER_MAIN)
    proc = subprocess.run([exe, str(bad)], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "halfvector" in proc.stdout


@pytest.mark.parametrize("mapping", ["deviation", "halfvector"])
def test_numpy_port_at_full_resolution_equals_kesbrdf_evaluate(any_model, rng, mapping):
    # up to 89°: γ reaches past γ_max + 6° (fade) and one cosine below a quarter of the other (bounded w)
    wi, wr = _pairs(rng, 3000, max_theta_deg=89.0)
    table, d_gamma = be.resample_table(any_model, any_model.phi_grid.size, any_model.gamma_grid.size)
    port = be.numpy_port(table, d_gamma, be._body3(any_model), wi, wr, halfvector=mapping == "halfvector", **be.lobe_parameters(any_model))
    ref = evaluate(any_model, wi, wr, mapping)
    np.testing.assert_allclose(port, ref, rtol=PORT_REL_TOL)


def test_the_shaders_default_mapping_is_the_models_own(tmp_path):
    """A new fit records the half-vector mapping: the exported shader defaults to it, and
    the downsampling check reads both sides with it (it compared a half-vector model with
    the deviation shader before, p90 error 0.21)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    m = measure(AnisotropicWard(0.1, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.08))
    for mapping, flag in (("halfvector", 1), ("deviation", 0)):
        model = fit(m, mapping=mapping)
        text, _ = be.brdf_explorer_source(model)
        assert f"bool halfvector {flag}\n" in text
        n_phi, n_gamma = be._default_grid(model)
        err = be.downsampling_error(model, n_phi, n_gamma)
        assert err["p90_rel"] < DOWNSAMPLE_P90_TOL and err["max_rel"] < DOWNSAMPLE_MAX_TOL, (mapping, err)


def test_default_table_downsampling_error_is_bounded(kes_model):
    n_phi, n_gamma = be._default_grid(kes_model)
    assert n_gamma == kes_model.gamma_grid.size  # γ is never resampled
    err = be.downsampling_error(kes_model, n_phi, n_gamma)
    assert err["p90_rel"] < DOWNSAMPLE_P90_TOL and err["max_rel"] < DOWNSAMPLE_MAX_TOL, err


def test_glsl_in_browser_equals_numpy_port(tmp_path, any_model, rng):
    node = shutil.which("node")
    chromium = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
    if node is None or chromium is None:
        pytest.skip("node and chromium are needed for the WebGL2 check (CI has both)")
    if not (VIEWER / "node_modules" / "playwright-core").is_dir():
        pytest.fail("viewer/node_modules/playwright-core is missing: run `make viewer`")
    n_phi = 12
    text, info = be.brdf_explorer_source(any_model, n_phi=n_phi)
    wi, wr = _pairs(rng, 1000)
    results = {}
    for halfvector in (0, 1):
        inp = tmp_path / f"in{halfvector}.json"
        out = tmp_path / f"out{halfvector}.json"
        inp.write_text(json.dumps({"glsl": _shader(text), "uniforms": {"scale": 1.0, "halfvector": halfvector, "tint": [1, 1, 1]}, "wi": wi.tolist(), "wr": wr.tolist()}))
        proc = subprocess.run([node, str(VIEWER / "scripts" / "glsl-eval.mjs"), str(inp), str(out)], cwd=VIEWER, capture_output=True, text=True, timeout=240)
        assert proc.returncode == 0, proc.stderr[-2000:]
        results[halfvector] = np.array(json.loads(out.read_text())["f"])
    table, d_gamma = be.resample_table(any_model, info["n_phi"], info["n_gamma"])
    for halfvector, f in results.items():
        port = be.numpy_port(table, d_gamma, be._body3(any_model), wi, wr, halfvector=bool(halfvector), **be.lobe_parameters(any_model))
        np.testing.assert_allclose(f, port, rtol=GLSL_REL_TOL, err_msg=f"halfvector={halfvector}")


def test_rejects_other_kinds_and_oversized_tables(tmp_path, kes_model):
    class Other:
        kind = "kes-halfdiff"

    with pytest.raises(KesbrdfError, match="'kes' model"):
        be.export(Other(), tmp_path / "x.brdf")
    with pytest.raises(KesbrdfError, match="constant-array limit"):
        be.export(kes_model, tmp_path / "x.brdf", n_phi=360)
    with pytest.raises(KesbrdfError, match=r"\.brdf"):
        be.export(kes_model, tmp_path / "x.txt")
