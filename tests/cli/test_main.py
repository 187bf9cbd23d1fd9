"""The CLI contract users and scripts rely on (real commands, real files)."""

import csv
import json

import numpy as np
import pytest

from kesbrdf.cli.main import main


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A simulated measurement and its `kesbrdf fit` model (read-only for the tests).
    Module-scoped: the auto fit compares with the fibre prior (~10 s CPU), once for the
    three tests that read it."""
    d = tmp_path_factory.mktemp("fitted")
    meas = d / "meas.csv"
    model = d / "model.kes.json"
    assert main(["simulate", "--reference", "ward", "-o", str(meas), "--noise", "0.01"]) == 0
    assert main(["fit", str(meas), "-o", str(model)]) == 0
    return meas, model


def test_simulate_writes_paper_protocol(tmp_path):
    out = tmp_path / "m.csv"
    assert main(["simulate", "-o", str(out)]) == 0
    lines = [l for l in out.read_text().splitlines() if not l.startswith("#")]
    assert len(lines) == 1 + 116
    assert "# simulated: true" in out.read_text()


def test_eval_matches_library_and_inputs(tmp_path, fitted):
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.io.model_file import load_model as load

    meas, model_path = fitted
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n60,180,30,0\n30,90,45,200\n")
    out = tmp_path / "out.csv"
    assert main(["eval", str(model_path), "--pairs", str(pairs), "-o", str(out), "--mapping", "halfvector"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert list(rows[0]) == ["theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg", "R", "G", "B"]
    model = load(model_path)
    wi = spherical_to_cartesian(np.radians(30), np.radians(90))
    wr = spherical_to_cartesian(np.radians(45), np.radians(200))
    expected = evaluate(model, wi, wr, "halfvector")
    assert float(rows[1]["G"]) == pytest.approx(expected[1], rel=1e-15)


def test_validate_prints_and_writes_json(tmp_path, fitted, capsys):
    meas, model = fitted
    js = tmp_path / "v.json"
    assert main(["validate", str(model), str(meas), "--json", str(js)]) == 0
    result = json.loads(js.read_text())
    assert result["metrics"]["all"]["rmse"] < 1e-12  # the model reproduces its inputs
    assert "rmse" in capsys.readouterr().out


def test_validate_says_whether_the_sigma_check_is_on_the_fitted_samples(tmp_path, fitted, capsys):
    """The coverage caveat named the fitted samples even for another file (found by trying
    the product); it now depends on whether the file is the one the model was fitted to."""
    meas, model = fitted
    capsys.readouterr()
    assert main(["validate", str(model), str(meas)]) == 0
    assert "these are the samples the model was fitted to" in capsys.readouterr().out
    other = tmp_path / "other.csv"
    assert main(["simulate", "--reference", "ward", "-o", str(other), "--noise", "0.01", "--seed", "5"]) == 0
    js = tmp_path / "v.json"
    assert main(["validate", str(model), str(other), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "not the file the model was fitted to" in out and "fitted to: a check" not in out
    assert json.loads(js.read_text())["uncertainty_on"] == "other data"


def test_eval_bad_pairs(tmp_path, fitted, capsys):
    _, model = fitted
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg\n1,2,3\n")
    out = tmp_path / "o.csv"
    assert main(["eval", str(model), "--pairs", str(pairs), "-o", str(out)]) == 2
    assert "missing column(s) phi_r_deg" in capsys.readouterr().err
    assert not out.exists()


def test_missing_model_file(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "nope.json"), str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "nope.json" in err and "Traceback" not in err


def test_demo_quick(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--quick"]) == 0
    v = json.loads((out / "validation.json").read_text())
    assert v["round_trip"]["metrics"]["all"]["rmse"] < 1e-9
    # issue 19: one fit; the one model file is the kind the fit chose, and the report names it
    from kesbrdf.io.model_file import load_model

    assert sorted(p.name for p in out.glob("model*.json")) == ["model.kes.json"]
    assert load_model(out / "model.kes.json").kind == v["fit_report"]["kind"] == v["model_kind"]
    assert f"<td class=txt>{v['model_sha256']}</td>" in (out / "report.html").read_text()
    # issue 9: the default model against the baselines, one verdict per case, consistent
    # with the stored RMSEs; the report carries the comparison, uncertainty and plan
    dvb = v["default_vs_baselines"]
    assert len(dvb["verdicts"]) == len(dvb["cases"]) == 3
    for line, (case, row) in zip(dvb["verdicts"], dvb["cases"].items()):
        wins = all(row[dvb["default"]]["rmse"] < row[b]["rmse"] for b in ("linear", "nearest"))
        assert line.startswith(case) and (line.endswith("beats linear and nearest") == wins), line
    html = (out / "report.html").read_text()
    # the prior's uncertainty map: the model's own when the fit chose the prior (issue 19:
    # the report is about the chosen model), else beside the chosen model
    prior_map = 'id="fig-6-uncertainty"' if load_model(out / "model.kes.json").has_sigma else 'id="fig-6-prior-uncertainty"'
    for anchor in ("<h3>Model comparison</h3>", 'id="fig-plan"', prior_map):
        assert anchor in html
    # issue 17: the time table counts the child processes' CPU too (the budget is the
    # whole demo's), so the total with children is never below the process's own
    t = json.loads((out / "demo_times.json").read_text())
    assert t["children_cpu_s"] >= 0
    assert t["total_cpu_with_children_s"] == pytest.approx(t["total_cpu_s"] + t["children_cpu_s"], abs=0.02)


def test_fit_routes_scattered_data_and_validate_uses_its_frame(tmp_path, capsys):
    """General-geometry data (CUReT corduroy) goes to the scattered fit (asked for here:
    auto would compare it with the fibre prior); validate turns the directions by the
    recorded warp offset."""
    from pathlib import Path

    from kesbrdf.io.measurement_csv import read_measurement, write_measurement

    allm = read_measurement(Path(__file__).parents[1] / "data" / "curet_fabrics.csv")
    k = [i for i, c in enumerate(allm.channels) if "corduroy" in c][0]
    one = allm.subset(np.ones(len(allm), bool))
    one.values = allm.values[:, [k]]
    one.channels = ("value",)
    one.uncertainty = None
    src = write_measurement(tmp_path / "corduroy.csv", one)
    model = tmp_path / "c.kes.json"
    assert main(["fit", str(src), "-o", str(model), "--kind", "scattered"]) == 0
    assert "scattered fit" in capsys.readouterr().err
    js = tmp_path / "v.json"
    assert main(["validate", str(model), str(src), "--json", str(js)]) == 0
    from kesbrdf.io.model_file import load_model as load
    from kesbrdf.models.scattered import evaluate_sample_frame
    from kesbrdf.validate.compare import metrics

    result = json.loads(js.read_text())["metrics"]["all"]
    m = read_measurement(src)
    expected = metrics(evaluate_sample_frame(load(model), m.wi, m.wr), m.values)["all"]
    assert result["rmse"] == pytest.approx(expected["rmse"], rel=1e-12)
    # training-set log error of the KES + body fit on corduroy measured 0.128
    assert result["log_rmse"] < 0.18


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["fit", "meas.csv"], "the following arguments are required: -o/--output"),
        (["fit", "meas.csv", "-o", "m.json", "--kind", "bogus"], "invalid choice: 'bogus'"),
        (["eval", "m.json", "--pairs", "p.csv", "-o", "o.csv", "--bogus"], "unrecognized arguments: --bogus"),
    ],
)
def test_argument_errors_are_one_line(argv, expected, capsys):
    """A mistyped command line is one stderr line naming the problem and --help, exit 2
    (argparse would print the whole usage block first)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert expected in lines[0]
    assert lines[0].startswith(f"kesbrdf {argv[0]}: error:")
    assert f"(see 'kesbrdf {argv[0]} --help')" in lines[0]


def test_a_mistyped_top_level_flag_is_the_top_level_parser_s_error(capsys):
    """`kesbrdf --bogus fit ...`: the flag is before the command, so the command is not blamed."""
    with pytest.raises(SystemExit) as exc:
        main(["--bogus", "fit", "m.csv", "-o", "m.json"])
    assert exc.value.code == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith("kesbrdf: error: unrecognized arguments: --bogus") and "\n" not in line


def test_export_agreement_is_one_short_line():
    """An analytic fit's record prints its error numbers, not a repr of its parameters."""
    from kesbrdf.cli.export import agreement_line

    line = agreement_line({"fit": {"material": "gltf_pbr", "params": {"base_color": [0.1, 0.2, 0.3]},
                                   "error": {"nrmse": 0.52812, "rel_l1": 0.37}},
                           "exact": False, "median_rel_err": 0.0178})
    assert line == "fit gltf_pbr: nrmse 0.5281, rel_l1 0.37; exact=False; median_rel_err=0.0178"
    assert "base_color" not in line and "\n" not in line


def test_export_agreement_says_which_parameters_hit_a_bound():
    """A fit at the edge of a physical range says so on the agreement line, per variant."""
    from kesbrdf.cli.export import agreement_line

    fit = {"material": "openpbr", "params": {}, "error": {"image_rmse": 0.07, "at_bounds": ["specular_ior max"]}}
    line = agreement_line({"fit": {"openpbr": fit},
                           "fit_error": {"openpbr": {"image_rmse": 0.0767, "nrmse": 0.469, "at_bounds": ["specular_ior max"]},
                                         "standard_surface": {"image_rmse": 0.0763, "nrmse": 0.468, "at_bounds": []}},
                           "exact": False})
    assert line == ("fit_error openpbr: image_rmse 0.0767, nrmse 0.469, at bound: specular_ior max; "
                    "fit_error standard_surface: image_rmse 0.0763, nrmse 0.468; exact=False")


def test_validate_says_where_the_error_is(tmp_path, fitted, capsys):
    """On its own samples the model has no error to place; on another protocol's samples
    validate prints one row per deviation band and --json keeps them."""
    meas, model = fitted
    capsys.readouterr()
    assert main(["validate", str(model), str(meas)]) == 0
    assert "nowhere above round-off" in capsys.readouterr().out
    dense = tmp_path / "dense.csv"
    assert main(["simulate", "--reference", "ward", "--protocol", "dense", "-o", str(dense), "--noise", "0.01"]) == 0
    js = tmp_path / "v.json"
    capsys.readouterr()
    assert main(["validate", str(model), str(dense), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    bands = json.loads(js.read_text())["by_deviation"]
    assert "by deviation from the mirror direction" in out
    assert out.count("of the squared error") == len(bands) >= 4
    assert sum(b["share"] for b in bands) == pytest.approx(1.0, abs=1e-9)
