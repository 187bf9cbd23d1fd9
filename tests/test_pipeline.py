"""The pipeline's steps (issue 19, docs/pipeline.md): one fit rule for the command, the
batch and the demo; the protocol read from the geometry; analytic fits shared."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf import pipeline
from kesbrdf.measure.gonio import measure
from kesbrdf.references.ward import AnisotropicWard

WARD = AnisotropicWard(0.1, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.08)


def test_protocol_is_read_from_the_geometry_not_the_labels():
    paper, dense = measure(WARD, protocol="paper"), measure(WARD, protocol="dense", step_deg=10)
    assert pipeline.protocol_of(paper) == "paper" and pipeline.protocol_of(dense) == "dense"
    # a label that lies changes nothing: the old batch rule read '"protocol": "dense"' from it
    paper.metadata["generator"] = '{"protocol": "dense"}'
    dense.metadata.pop("generator")
    assert pipeline.protocol_of(paper) == "paper" and pipeline.protocol_of(dense) == "dense"
    # one row out of the plane: no protocol re-measures it
    import dataclasses

    psi, phi_r = paper.psi.copy(), paper.phi_r.copy()
    psi[0], phi_r[0] = np.nan, phi_r[0] + 0.5
    general = dataclasses.replace(paper, psi=psi, phi_r=phi_r)
    assert pipeline.protocol_of(general) is None


def _record_fit_calls(monkeypatch):
    import kesbrdf.fitting

    calls = []
    real = kesbrdf.fitting.fit

    def spy(m, kind="auto", strict=False, compare=True, **options):
        calls.append({"kind": kind, "strict": strict, "compare": compare, "options": options})
        return real(m, kind=kind, strict=strict, compare=False, **options)  # the check is the call, keep it cheap

    monkeypatch.setattr(kesbrdf.fitting, "fit", spy)
    monkeypatch.setattr("kesbrdf.fit", spy)
    return calls


@pytest.mark.parametrize("row, argv", [
    ({"kind": "", "orientations": "", "fallback": None}, []),
    ({"kind": "kes", "orientations": 4, "fallback": "log"}, ["--kind", "kes", "--orientations", "4", "--fallback", "log"]),
])
def test_batch_fits_by_the_rule_of_kesbrdf_fit(tmp_path, monkeypatch, row, argv):
    """A catalogue row and the same options on ``kesbrdf fit`` call :func:`kesbrdf.fit`
    identically (the old batch passed compare=False, so a fabric could get another model)."""
    from kesbrdf.batch.steps import fit_model
    from kesbrdf.cli.main import main
    from kesbrdf.io.measurement_csv import write_measurement

    m = measure(WARD, protocol="paper")
    path = tmp_path / "m.csv"
    write_measurement(path, m)
    calls = _record_fit_calls(monkeypatch)
    assert main(["fit", str(path), "-o", str(tmp_path / "m.kes.json"), *argv]) == 0
    fitted = fit_model(m, row)
    assert len(calls) == 2 and calls[0] == calls[1], calls
    assert calls[0]["compare"] is True and isinstance(fitted, pipeline.Fitted)
    # the same model and hash from the file the command wrote
    from kesbrdf.io.model_file import load_model

    assert pipeline.model_sha256(load_model(tmp_path / "m.kes.json")) == fitted.sha256


def test_validate_holds_out_in_the_measurements_protocol():
    m = measure(WARD, protocol="dense", step_deg=10)
    m.metadata.pop("generator")  # nothing to read the protocol from but the directions
    fitted = pipeline.fit(m, pipeline.FitSpec("kes-halfdiff"))
    v = pipeline.validate(fitted, m, WARD, baselines=False)
    assert v.held_out["protocol"] == "dense" and v.leave_one_orientation_out is None
    # the held-out numbers are the model against the reference re-measured densely at 22.5/67.5 deg
    from kesbrdf.validate.compare import HELD_OUT_DEG, validate

    held = measure(WARD, protocol="dense", orientations_deg=HELD_OUT_DEG)
    assert v.numbers()["ref_nrmse"] == pytest.approx(validate(fitted.model, held)["metrics"]["all"]["nrmse"], rel=1e-12)
    assert v.numbers()["fit_nrmse"] < 1e-6  # the half/difference table interpolates its own samples


def test_export_step_fits_each_analytic_material_once_and_keeps_it_beside_the_outputs(tmp_path, monkeypatch):
    """glTF + glb share one glTF fit, MaterialX + USD one OpenPBR fit; the fits are kept in
    ``fit_cache_dir`` and a new process (memory cleared) reads them instead of refitting."""
    pytest.importorskip("scipy")
    pytest.importorskip("pygltflib")
    pytest.importorskip("MaterialX")
    pytest.importorskip("pxr")
    from kesbrdf.export import analytic_fit, fit_cache
    from kesbrdf.pipeline import outputs

    small = ((3, 6), (4, 8))  # the check is the sharing, not the fit quality (tests/export)
    model = pipeline.fit(measure(WARD, protocol="paper"), pipeline.FitSpec("kes"))
    fitted_materials = []
    real = analytic_fit.fit_analytic_uncached

    def spy(material, *a, **k):
        fitted_materials.append(material.name)
        return real(material, *a, **k)

    monkeypatch.setattr(analytic_fit, "fit_analytic_uncached", spy)
    monkeypatch.setenv(fit_cache.CACHE_ENV, "off")  # only the folder given below
    fit_cache.clear_memory()
    formats = ("gltf", "glb", "mtlx", "usd")
    opts = {"*": {"fit_grid": small, "error_grid": small}}
    cache = tmp_path / "out" / "analytic-fits"
    got = outputs.export(model, tmp_path / "out", formats, options=opts, fit_cache_dir=cache)
    assert sorted(got.results) == sorted(formats) and got.failed == {}
    assert sorted(fitted_materials) == ["gltf_pbr", "openpbr", "preview_surface", "standard_surface"]
    assert len(list(cache.glob("*.json"))) == 4
    fit_cache.clear_memory()
    again = outputs.export(model, tmp_path / "again", formats, options=opts, fit_cache_dir=cache)
    assert len(fitted_materials) == 4 and sorted(again.results) == sorted(formats)
    assert again.results["gltf"].agreement["fit"] == got.results["gltf"].agreement["fit"]
