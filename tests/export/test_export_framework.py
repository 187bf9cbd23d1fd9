"""The export framework: dispatch on FORMATS, checks before work, atomic output, the CLI."""

import sys
import types

import numpy as np
import pytest

from kesbrdf._atomic import write_text
from kesbrdf.cli.main import main
from kesbrdf.errors import ExportError
from kesbrdf.export import FORMATS, ExportResult, export

TOY = "_kesbrdf_test.toyformat"


@pytest.fixture(scope="module")
def model():
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    return fit(measure(AnisotropicWard(0.1, 0.2, rho_d=[0.3, 0.2, 0.1], rho_s=0.1)))


@pytest.fixture
def toy(monkeypatch):
    """A format that writes the model's body term as text and records its calls."""
    mod = types.ModuleType(TOY)
    mod.EXTENSIONS = (".toy",)
    mod.HELP = "test format"
    mod.calls = []

    def _export(model, out, scale=1.0):
        mod.calls.append(out)
        write_text(out, " ".join(f"{v * scale:.6g}" for v in model.body))
        return ExportResult("toy", [out], agreement={"max_rel_err": 0.0}, open_with="a text editor")

    mod.export = _export
    monkeypatch.setitem(sys.modules, TOY, mod)
    monkeypatch.setitem(FORMATS, "toy", TOY)
    return mod


def test_dispatch_writes_and_reports_size(tmp_path, model, toy):
    out = tmp_path / "sub" / "m.toy"
    result = export(model, "toy", out, scale=2.0)
    assert result.paths == [out]
    assert result.size == out.stat().st_size > 0
    np.testing.assert_allclose([float(v) for v in out.read_text().split()], 2 * model.body, rtol=1e-5)


def test_model_path_is_loaded(tmp_path, model, toy):
    path = tmp_path / "m.kes.json"
    model.save(path)
    result = export(path, "toy", tmp_path / "a.toy")
    assert result.paths[0].read_text().split()[0] == f"{model.body[0]:.6g}"


@pytest.mark.parametrize(
    "fmt, out, options, message",
    [
        ("nope", "m.toy", {}, "expected an export format"),
        ("toy", "m.txt", {}, "ending in .toy"),
        ("toy", "m.toy", {"colour": 1}, "unknown option(s) 'colour'"),
    ],
)
def test_bad_requests_fail_before_any_work(tmp_path, model, toy, fmt, out, options, message):
    with pytest.raises(ExportError, match=message.replace("(", r"\(").replace(")", r"\)")):
        export(model, fmt, tmp_path / out, **options)
    assert toy.calls == []
    assert list(tmp_path.iterdir()) == []


def test_folder_as_output_is_refused(tmp_path, model, toy):
    (tmp_path / "d.toy").mkdir()
    with pytest.raises(ExportError, match="folder"):
        export(model, "toy", tmp_path / "d.toy")


def test_cli_prints_what_was_written(tmp_path, model, toy, capsys):
    path = tmp_path / "m.kes.json"
    model.save(path)
    out = tmp_path / "m.toy"
    assert main(["export", str(path), "--format", "toy", "-o", str(out), "-O", "scale=3"]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out}" in text and "max_rel_err=0" in text and "open with: a text editor" in text
    np.testing.assert_allclose(float(out.read_text().split()[0]), 3 * model.body[0], rtol=1e-5)


def test_cli_user_errors_exit_2_without_traceback(tmp_path, model, toy, capsys):
    path = tmp_path / "m.kes.json"
    model.save(path)
    assert main(["export", str(path), "--format", "toy", "-o", str(tmp_path / "m.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "ending in .toy" in err
    assert main(["export", str(path), "--format", "toy", "-o", str(tmp_path / "m.toy"), "-O", "bad"]) == 2
    assert main(["export", str(tmp_path / "missing.kes.json"), "--format", "toy", "-o", str(tmp_path / "x.toy")]) == 2


def test_cli_rgl_bsdf_reports_size_agreement_and_client(tmp_path, model, capsys):
    path = tmp_path / "m.kes.json"
    model.save(path)
    out = tmp_path / "m.bsdf"
    opts = ["-O", "n_theta_i=5", "-O", "n_phi_i=9", "-O", "n=16", "-O", "n_ndf=16"]
    assert main(["export", str(path), "--format", "rgl-bsdf", "-o", str(out)] + opts) == 0
    text = capsys.readouterr().out
    assert f"wrote {out} (" in text and "KiB)" in text
    assert "median_rel_err=" in text and "p90_rel_err_grazing=" in text
    assert 'open with: Mitsuba 3 (RGB variants): <bsdf type="measured"><string name="filename" value="m.bsdf"/>' in text
    assert out.read_bytes()[:12] == b"tensor_file\0"


def test_cli_lists_the_formats(capsys):
    assert main(["export", "--list"]) == 0
    text = capsys.readouterr().out
    for name in ("rgl-bsdf", "rgl-bsdf-spectral", "mitsuba-scene"):
        assert name in text


def test_bad_grid_option_is_a_one_line_error(tmp_path, model):
    with pytest.raises(ExportError, match="option n_phi_i: expected an integer >= 3"):
        export(model, "rgl-bsdf", tmp_path / "m.bsdf", n_phi_i=2)
    assert not (tmp_path / "m.bsdf").exists()


def test_a_format_returning_a_dict_is_refused_in_one_line(tmp_path, model, toy):
    """The framework's one contract: ``export()`` returns an ExportResult; a dict is refused."""
    toy.export = lambda model, out, scale=1.0: {"paths": [str(out)], "max_rel_err": 0.0}
    with pytest.raises(ExportError) as exc:
        export(model, "toy", tmp_path / "m.toy")
    text = str(exc.value)
    assert "\n" not in text and "ExportResult" in text and "dict" in text and text.startswith("toy:")


#: Cheap options per format option name: the analytic formats get precomputed fits on
#: the small grid (tests/export/conftest.py), the tensor formats a coarse grid.
def _cheap_options(module, fits) -> dict:
    import inspect

    params = inspect.signature(module.export).parameters
    opts = {}
    if "fit" in params:
        opts["fit"] = fits["gltf_pbr"]
    if "fits" in params:
        opts["fits"] = {k: v for k, v in fits.items() if k != "gltf_pbr"}
    for name, value in (("n_theta_i", 5), ("n_phi_i", 5), ("n", 8), ("n_ndf", 8), ("check", False),
                        ("width", 16), ("height", 12), ("spp", 1), ("n_phi", 16), ("n_gamma", 16)):
        if name in params:
            opts[name] = value
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):  # mitsuba-scene: options of its .bsdf
        opts.update(n_theta_i=5, n_phi_i=5, n=8, n_ndf=8)
    return opts


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_every_registered_format_returns_an_export_result(tmp_path, kes_model, fits, fmt):
    """Every name in ``FORMATS`` (a new format is covered without editing this test)
    writes through the framework and reports an ExportResult naming files that exist."""
    from kesbrdf.export import format_module

    try:
        module = format_module(fmt)
    except ImportError as exc:
        pytest.skip(f"{fmt}: optional dependency missing ({exc})")
    ext = (getattr(module, "EXTENSIONS", ()) or (".out",))[0]
    try:
        result = export(kes_model, fmt, tmp_path / f"m{ext}", **_cheap_options(module, fits))
    except ImportError as exc:
        pytest.skip(f"{fmt}: optional dependency missing ({exc})")
    assert isinstance(result, ExportResult) and result.format == fmt
    assert result.paths and all(p.is_file() for p in result.paths)
    assert result.size == sum(p.stat().st_size for p in result.paths) > 0
    assert result.to_json()["format"] == fmt  # JSON-ready: the demo and batch write it as is
