"""The model contract (issue 19): every command works on every registered kind.

A small model of each kind in :func:`kesbrdf.models.base.known_kinds` is fitted once, and
every command runs on it in-process: ``report``, ``plot`` (each figure), ``validate``,
``render`` (tiny), ``export`` in every format of the export registry, and ``view`` (the
server starts, serves the model, stops).  Each either exits 0 with its outputs written,
or exits 2 with a one-line message on stderr; never a traceback.  A toy kind defined in
this module and registered in-process is covered by the same code without other edits.
"""

from __future__ import annotations

import http.client
import json
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.models import base

#: Small grids for the exports' analytic fits and tensor files: the contract checks that
#: every format writes a file for every kind, not the fit quality (tests/export/ do).
SMALL_FIT_GRID = [[4, 8], [6, 12]]
EXPORT_OPTIONS = {
    "rgl-bsdf": ["n_theta_i=5", "n_phi_i=9", "n=16", "n_ndf=16", "check=false"],
    "rgl-bsdf-spectral": ["n_theta_i=5", "n_phi_i=9", "n=16", "n_ndf=16", "check=false"],
    "mitsuba-scene": ["n_theta_i=5", "n_phi_i=9", "n=16", "n_ndf=16", "check=false"],
    "gltf": [f"fit_grid={json.dumps(SMALL_FIT_GRID)}", f"error_grid={json.dumps(SMALL_FIT_GRID)}"],
    "glb": [f"fit_grid={json.dumps(SMALL_FIT_GRID)}", f"error_grid={json.dumps(SMALL_FIT_GRID)}"],
    "mtlx": [f"fit_grid={json.dumps(SMALL_FIT_GRID)}", f"error_grid={json.dumps(SMALL_FIT_GRID)}"],
    "usd": [f"fit_grid={json.dumps(SMALL_FIT_GRID)}", f"error_grid={json.dumps(SMALL_FIT_GRID)}"],
}
FIGURES = ("3a", "3b", "4", "5", "6", "albedo")
#: Seconds a test waits for the viewer server (a shared, loaded machine).
TIMEOUT = 30


def _measurements(folder: Path) -> list[Path]:
    """Two small simulated measurements of a satin-like fabric (one channel): the paper's
    protocol (one incidence line, 116 rows) and a dense one (several incidence angles).
    A kind is fitted to the first it uses every row of."""
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.measure.gonio import measure
    from kesbrdf.references.ward import AnisotropicWard

    ref = AnisotropicWard(alpha_x=0.1, alpha_y=0.25, rho_d=0.1, rho_s=0.1)
    paths = []
    for name, kwargs in (("paper", {}), ("dense", {"protocol": "dense", "step_deg": 15})):
        path = folder / f"{name}.csv"
        write_measurement(path, measure(ref, **kwargs))
        paths.append(path)
    return paths


def fit_kind(kind: str, folder: Path) -> tuple[Path, Path]:
    """(model file, measurement file) of a small model of ``kind``."""
    import kesbrdf
    from kesbrdf.io.measurement_csv import read_measurement

    folder.mkdir(parents=True, exist_ok=True)
    for meas_path in _measurements(folder):
        m = read_measurement(meas_path)
        mask, _ = base.fitter_class(kind).usable_rows(m)
        if np.all(mask):
            model, _ = kesbrdf.fit(m, kind=kind, compare=False)
            path = folder / f"{kind}.kes.json"
            model.save(path)
            return path, meas_path
    raise AssertionError(f"no contract measurement that kind {kind!r} uses every row of")


def _check_outcome(rc, err: str, outputs, what: str) -> str:
    """rc 0 with the outputs written, or rc 2 with one line on stderr; never a traceback."""
    assert "Traceback" not in err, f"{what}: traceback\n{err}"
    if rc == 0:
        for out in outputs:
            assert Path(out).is_file() and Path(out).stat().st_size > 0, f"{what}: {out} not written"
        return "ok"
    assert rc == 2, f"{what}: exit {rc}\n{err}"
    lines = [line for line in err.strip().splitlines() if line.startswith("kesbrdf")]
    assert len(lines) == 1 and lines[0].startswith("kesbrdf: error: "), f"{what}: expected one error line\n{err}"
    return lines[0]


def _view(model_path: Path, monkeypatch) -> dict:
    """``kesbrdf view MODEL`` in-process: the server starts, serves the model, stops."""
    import kesbrdf.viewer.server as server_module

    real = server_module.make_server
    seen = {}

    def make_server(**kwargs):
        srv = real(**kwargs)

        def serve_once(*_a, **_k):
            thread = threading.Thread(target=srv_serve, kwargs={"poll_interval": 0.02}, daemon=True)
            thread.start()
            try:
                host, port = srv.server_address[:2]
                for url in ("/api/models", None):
                    if url is None:
                        url = f"/api/model/{seen['models']['models'][0]['id']}"
                    conn = http.client.HTTPConnection(host, port, timeout=TIMEOUT)
                    conn.request("GET", url)
                    resp = conn.getresponse()
                    body = json.loads(resp.read())
                    conn.close()
                    seen["models" if url == "/api/models" else "model"] = body
                    seen.setdefault("status", []).append(resp.status)
            finally:
                srv.shutdown()
                thread.join(TIMEOUT)

        srv_serve = srv.serve_forever
        srv.serve_forever = serve_once
        return srv

    monkeypatch.setattr(server_module, "make_server", make_server)
    seen["rc"] = main(["view", str(model_path), "--port", "0", "--no-browser"])
    return seen


def run_contract(model_path: Path, meas_path: Path, out: Path, capsys, monkeypatch) -> dict:
    """Every command on one model file; returns {command: "ok" or the one-line error}."""
    from kesbrdf.export import FORMATS

    out.mkdir(parents=True, exist_ok=True)
    commands = {
        "report": (["report", str(model_path), "--measurement", str(meas_path), "-o", str(out / "r.html")],
                   [out / "r.html"]),
        "validate": (["validate", str(model_path), str(meas_path), "--json", str(out / "v.json")], [out / "v.json"]),
        "render": (["render", str(model_path), "-o", str(out / "s.png"), "--resolution", "32x24", "--spp", "4"],
                   [out / "s.png"]),
    }
    for fig in FIGURES:
        commands[f"plot {fig}"] = (["plot", str(model_path), "--figure", fig, "-o", str(out / f"f{fig}.png"), "--dpi", "40"],
                                   [out / f"f{fig}.png"])
    endings = {"rgl-bsdf": ".bsdf", "rgl-bsdf-spectral": ".bsdf", "mitsuba-scene": ".xml", "gltf": ".gltf",
               "glb": ".glb", "mtlx": ".mtlx", "usd": ".usda", "brdf-explorer": ".brdf"}
    for fmt in FORMATS:
        target = out / f"x-{fmt}{endings.get(fmt, '')}"
        argv = ["export", str(model_path), "--format", fmt, "-o", str(target)]
        for opt in EXPORT_OPTIONS.get(fmt, ()):
            argv += ["-O", opt]
        commands[f"export {fmt}"] = (argv, [target])
    outcome = {}
    capsys.readouterr()
    for name, (argv, outputs) in commands.items():
        rc = main(argv)
        err = capsys.readouterr().err
        outcome[name] = _check_outcome(rc, err, outputs, f"{model_path.name}: {name}")
    seen = _view(model_path, monkeypatch)
    err = capsys.readouterr().err
    if seen["rc"] != 0:  # refused before serving: exit 2 and one line
        outcome["view"] = _check_outcome(seen["rc"], err, [], f"{model_path.name}: view")
        return outcome
    assert seen["status"][0] == 200 and seen["status"][1] in (200, 422), seen["status"]
    if seen["status"][1] == 200:
        doc = seen["model"]["model"]
        # the viewer's shaders draw the (phi, gamma) table format: every kind arrives as one
        assert doc["format"] == "kesbrdf-model" and {"table", "phi_grid", "gamma_grid", "body"} <= set(doc["arrays"])
        outcome["view"] = "ok"
    else:  # the model cannot be drawn: one line, and the server goes on serving
        message = seen["model"]["error"]
        assert message and "\n" not in message
        outcome["view"] = message
    capsys.readouterr()
    return outcome


@pytest.fixture(scope="session")
def kind_models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("contract")
    return {kind: fit_kind(kind, folder / kind.replace("-", "_")) for kind in base.known_kinds()}


@pytest.mark.parametrize("kind", base.known_kinds())
def test_every_command_works_on_every_kind(kind, kind_models, tmp_path, capsys, monkeypatch):
    model_path, meas_path = kind_models[kind]
    outcome = run_contract(model_path, meas_path, tmp_path / "out", capsys, monkeypatch)
    # every registered kind is drawn, reported, validated, rendered, exported and viewed:
    # no command refuses any of them today (a refusal would be a one-line exit 2)
    assert outcome == dict.fromkeys(outcome, "ok"), {k: v for k, v in outcome.items() if v != "ok"}


# ------------------------------------------------------------------------------------
# a toy kind, defined here and registered in-process: the contract covers it unchanged
# ------------------------------------------------------------------------------------
@dataclass
class ToyModel(base.ReflectanceModel):
    """A Lambertian body plus a fixed anisotropic Ward-like lobe; fitted: the albedo and the
    lobe weight per channel by least squares (two parameters per channel)."""

    kind: ClassVar[str] = "toy-ward"
    mappings: ClassVar[tuple[str, ...]] = ("deviation",)
    fit_options: ClassVar[tuple[str, ...]] = ()
    array_names: ClassVar[tuple[str, ...]] = ("coef",)

    channels: tuple
    coef: np.ndarray  # (2, C): body 1/sr, lobe weight
    parameters: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    input_info: dict = field(default_factory=dict)
    kesbrdf_version: str = base.__version__

    @staticmethod
    def basis(wi, wr) -> np.ndarray:
        """(n, 2): 1 and the unit-weight lobe, an anisotropic Ward with α = (0.1, 0.25)."""
        h = wi + wr
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        ax, ay = 0.1, 0.25
        e = -((h[:, 0] / ax) ** 2 + (h[:, 1] / ay) ** 2) / h[:, 2] ** 2
        lobe = np.exp(e) / (4 * math.pi * ax * ay * np.sqrt(wi[:, 2] * wr[:, 2]))
        return np.stack([np.ones_like(lobe), lobe], axis=-1)

    def evaluate_unit(self, wi, wr, mapping):
        return self.basis(wi, wr) @ self.coef

    def to_payload(self):
        return {}, {"coef": self.coef}

    @classmethod
    def from_payload(cls, fields, arrays, shared, source=None):
        return cls(coef=np.asarray(arrays["coef"], float), **shared)

    @classmethod
    def usable_rows(cls, measurement):
        return np.ones(len(measurement), bool), ""

    @classmethod
    def fit_measurement(cls, measurement, **options):
        A = cls.basis(measurement.wi, measurement.wr)
        coef = np.maximum(np.linalg.lstsq(A, measurement.values, rcond=None)[0], 0.0)
        return cls(channels=tuple(measurement.channels), coef=coef, input_info=measurement.input_info())


@pytest.fixture
def toy_kind():
    """Register :class:`ToyModel` for one test and restore the registry afterwards."""
    saved = [dict(d) for d in (base.KIND_MODULES, base.FIT_MODULES, base._REGISTRY, base._FITTERS)]
    base.register(ToyModel)
    yield ToyModel.kind
    for d, old in zip((base.KIND_MODULES, base.FIT_MODULES, base._REGISTRY, base._FITTERS), saved):
        d.clear()
        d.update(old)


@pytest.mark.slow  # every command again on a toy kind (~10 s): make test-long, which CI runs
def test_a_new_kind_is_covered_without_other_edits(toy_kind, tmp_path, capsys, monkeypatch):
    assert toy_kind in base.known_kinds()
    model_path, meas_path = fit_kind(toy_kind, tmp_path)
    outcome = run_contract(model_path, meas_path, tmp_path / "out", capsys, monkeypatch)
    assert outcome == dict.fromkeys(outcome, "ok"), {k: v for k, v in outcome.items() if v != "ok"}


class NoTableModel(ToyModel):
    """A toy kind that cannot be tabulated: the views that need a (φ, γ) table say so in one
    line, and everything else still works."""

    kind: ClassVar[str] = "toy-no-table"

    def table_view(self, n_phi=None, n_gamma=None):
        from kesbrdf.errors import ModelError

        raise ModelError(f"a {self.kind!r} model has no (phi, gamma) table view (a test kind)")


def test_a_view_that_cannot_be_drawn_is_one_line_and_the_rest_runs(tmp_path, capsys, monkeypatch):
    saved = [dict(d) for d in (base.KIND_MODULES, base.FIT_MODULES, base._REGISTRY, base._FITTERS)]
    try:
        base.register(NoTableModel)
        model_path, meas_path = fit_kind(NoTableModel.kind, tmp_path)
        outcome = run_contract(model_path, meas_path, tmp_path / "out", capsys, monkeypatch)
    finally:
        for d, old in zip((base.KIND_MODULES, base.FIT_MODULES, base._REGISTRY, base._FITTERS), saved):
            d.clear()
            d.update(old)
    needs_table = {"plot 5", "render", "export brdf-explorer", "export mitsuba-scene", "view"}
    refused = {k for k, v in outcome.items() if v != "ok"}
    assert refused == needs_table, outcome
    for name in needs_table - {"view"}:
        assert "has no (phi, gamma) table view" in outcome[name], (name, outcome[name])
    assert "has no (phi, gamma) table view" in outcome["view"]
    # the report says so for its table summary and figure 5, and draws everything else
    html = (tmp_path / "out" / "r.html").read_text()
    assert "has no (phi, gamma) table view" in html and "Figure 5 not drawn" in html


#: The tabulated view reproduces the model at the table's nodes on the paper's line
#: (the lookup is exact there up to round-off: 1e-9 relative).
NODE_RTOL = 1e-9


def test_library_capabilities_of_the_toy_kind(toy_kind, tmp_path):
    """The library entry points on the toy kind: describe, table view, σ, plugin, refit."""
    import kesbrdf
    from kesbrdf.geometry import in_plane_directions
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.validate.compare import validate

    m = read_measurement(_measurements(tmp_path)[0])
    model, report = kesbrdf.fit(m, kind=toy_kind)
    assert report.kind == toy_kind and model.describe().startswith(toy_kind)
    assert validate(model, m)["metrics"]["all"]["nrmse"] < 1e-6  # the toy's own family: exact
    table = model.table_view()
    assert not model.has_table and table.kind == "kes" and table.parameters["tabulated_from"] == toy_kind
    psi, gamma = np.meshgrid(table.phi_grid[::45], table.gamma_grid[::11], indexing="ij")
    wi, wr = in_plane_directions(psi, np.pi / 4 - gamma / 2, np.pi / 4 + gamma / 2)
    np.testing.assert_allclose(evaluate(table, wi, wr), evaluate(model, wi, wr), rtol=NODE_RTOL, atol=1e-12)
    assert model.predict_sigma(wi.reshape(-1, 3), wr.reshape(-1, 3)) is None and not model.has_sigma
    assert model.render_plugin() == ("kesbrdf", {})
    held = m.is_in_plane & (np.abs(np.degrees(m.psi) - 45.0) < 0.5)
    refit = model.refit(~held)  # the measurement of this session's fit
    assert refit.kind == toy_kind
    # the held-out orientation is predicted from the others (the toy's family: exact again)
    held_m = m.subset(held)
    np.testing.assert_allclose(evaluate(refit, held_m.wi, held_m.wr), held_m.values, rtol=1e-6)


# ------------------------------------------------------------------------------------
# the capabilities on the registered kinds
# ------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", base.known_kinds())
def test_table_view_reproduces_every_kind_on_the_paper_line(kind, kind_models):
    """The (φ, γ) view (figure 5, shaders, viewer) equals the model at its nodes on the
    paper's line θ_i + θ_r = 90° (NODE_RTOL), and is reciprocal (deviation mapping)."""
    from kesbrdf.geometry import in_plane_directions
    from kesbrdf.io.model_file import load_model
    from kesbrdf.models.brdf import evaluate

    model = load_model(kind_models[kind][0])
    table = model.table_view()
    assert table.kind == base.TABLE_KIND and table.has_table and table.table_view() is table
    assert model.has_table == (table is model)
    g_max = min(float(table.gamma_grid[-1]), math.radians(88.0))
    gammas = table.gamma_grid[table.gamma_grid <= g_max][::7]
    psi, gamma = np.meshgrid(table.phi_grid[::30], gammas, indexing="ij")
    wi, wr = in_plane_directions(psi, np.pi / 4 - gamma / 2, np.pi / 4 + gamma / 2)
    f_model = evaluate(model, wi, wr)
    np.testing.assert_allclose(evaluate(table, wi, wr), f_model, rtol=NODE_RTOL, atol=1e-12 * f_model.max())
    np.testing.assert_allclose(evaluate(table, wr, wi), evaluate(table, wi, wr), rtol=NODE_RTOL)


@pytest.mark.parametrize("kind", base.known_kinds())
def test_refit_on_every_row_gives_the_same_model(kind, kind_models):
    """``refit`` is the same fit: on every row of the measurement it reproduces the model
    (same fitter, same options; deterministic fits: 1e-9 relative), and a model read from
    a file without its measurement says so in one line."""
    from kesbrdf.errors import ModelError
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.io.model_file import load_model
    from kesbrdf.models.brdf import evaluate

    model_path, meas_path = kind_models[kind]
    model, m = load_model(model_path), read_measurement(meas_path)
    with pytest.raises(ModelError, match="expected the measurement it was fitted to") as err:
        model.refit(np.ones(len(m), bool))
    assert "\n" not in str(err.value)
    again = model.refit(np.ones(len(m), bool), m)
    assert again.kind == model.kind
    np.testing.assert_allclose(evaluate(again, m.wi, m.wr), evaluate(model, m.wi, m.wr), rtol=1e-9, atol=1e-12)


def test_sigma_is_asked_not_named(kind_models):
    """Only kinds that carry a σ give one; σ ≥ 0 and f is the model's own prediction."""
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.io.model_file import load_model

    for kind, (model_path, meas_path) in kind_models.items():
        model, m = load_model(model_path), read_measurement(meas_path)
        result = model.predict_sigma(m.wi, m.wr)
        assert (result is not None) == model.has_sigma, kind
        if result is not None:
            f, sigma, _ = result
            assert np.all(sigma >= 0)
            np.testing.assert_allclose(f, model.evaluate(m.wi, m.wr), rtol=1e-9, atol=1e-12)


def test_report_on_a_scattered_fit_with_its_measurement(tmp_path, capsys):
    """Issue 19: ``kesbrdf report`` on a scattered fit with ``--measurement`` of scattered
    data ended in a TypeError; leave-one-orientation-out now records a one-line reason
    (no orientation ψ to hold out) and the rest of the report is written."""
    from kesbrdf.io.measurement_csv import read_measurement, write_measurement
    from kesbrdf.measure.measurement import Measurement

    dense = read_measurement(_measurements(tmp_path)[1])
    # the viewer turned 10 deg out of the plane of incidence: general rows with no psi (rows
    # in the plane would read back as in-plane samples, docs/formats.md)
    scattered = Measurement(dense.theta_i, dense.phi_i, dense.theta_r, dense.phi_r + np.radians(10), dense.values)
    meas, model, report = tmp_path / "scattered.csv", tmp_path / "s.kes.json", tmp_path / "r.html"
    write_measurement(meas, scattered)
    assert main(["fit", str(meas), "--kind", "scattered", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["report", str(model), "--measurement", str(meas), "-o", str(report)]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "leave-one-orientation-out needs in-plane samples" in report.read_text()
