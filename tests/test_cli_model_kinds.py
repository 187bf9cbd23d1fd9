"""The CLI on every model kind: `fit` says which kind and how many rows, consumers give
one-line errors for kinds or mappings they do not support (issue 8)."""

import contextlib
import io
import json

import pytest

from kesbrdf.cli.main import main


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    d = tmp_path_factory.mktemp("dense")
    meas, model = d / "dense.csv", d / "dense.kes.json"
    assert main(["simulate", "--protocol", "dense", "--step-deg", "10", "-o", str(meas)]) == 0
    # the fit's own stderr, kept for the test that reads it (a dense default fit is the
    # slowest step here: it runs once)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["fit", str(meas), "-o", str(model)]) == 0
    return meas, model, err.getvalue()


def test_fit_on_dense_data_chooses_halfdiff_and_says_so(dense):
    meas, out, err = dense
    n = sum(1 for line in meas.read_text().splitlines() if line and not line.startswith("#")) - 1
    assert f"kind kes-halfdiff: uses every row (several incidence angles per orientation); uses {n} of {n} rows" in err
    assert json.loads(out.read_text())["kind"] == "kes-halfdiff"


def test_fit_on_the_demo_measurement_succeeds_with_a_warning(tmp_path, capsys):
    from kesbrdf.measure import demo_data
    from kesbrdf.measure.acquisition.ingest import ingest
    from kesbrdf.io.measurement_csv import write_measurement

    meas = tmp_path / "measurement.csv"
    write_measurement(meas, ingest(demo_data.embedded_manifest()).measurement)
    capsys.readouterr()
    # --no-compare: the kes fit itself (kind=auto would keep prior + residual on this satin)
    assert main(["fit", str(meas), "-o", str(tmp_path / "m.kes.json"), "--no-compare"]) == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert len(warnings) == 1 and "K(phi) = 1/rho <= 0" in warnings[0] and "gamma = " in warnings[0]
    assert main(["fit", str(meas), "-o", str(tmp_path / "strict.kes.json"), "--strict"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("kesbrdf: error: K(phi) = 1/rho <= 0") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "strict.kes.json").exists()


def test_option_not_for_the_chosen_kind_is_an_error(dense, tmp_path, capsys):
    meas, _, _ = dense
    assert main(["fit", str(meas), "-o", str(tmp_path / "x.kes.json"), "--interpolation", "linear"]) == 2
    err = capsys.readouterr().err.strip()
    assert "interpolation (accepted by kes) do not apply to kind 'kes-halfdiff'" in err and "\n" not in err


@pytest.mark.parametrize("argv,message", [
    (["eval", "{model}", "--pairs", "{tmp}/none.csv", "--mapping", "paper", "-o", "{tmp}/o.csv"],
     "a 'kes-halfdiff' model supports mapping 'halfdiff'; got 'paper'"),
])
def test_consumers_refuse_unsupported_kinds_in_one_line(dense, tmp_path, capsys, argv, message):
    _, model, _ = dense
    argv = [a.format(model=model, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"kesbrdf: error: {message}"


def test_eval_and_figure_6_work_on_halfdiff(dense, tmp_path):
    _, model, _ = dense
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n30,180,30,0\n90,0,10,0\n")
    out = tmp_path / "o.csv"
    assert main(["eval", str(model), "--pairs", str(pairs), "-o", str(out)]) == 0
    rows = out.read_text().splitlines()
    assert float(rows[1].split(",")[4]) > 0 and float(rows[2].split(",")[4]) == 0.0  # θ_i = 90°: 0
    assert main(["plot", str(model), "--figure", "6", "-o", str(tmp_path / "f6.png")]) == 0
    # the panel names the model's kind (it said "model (KES, ...)" for every kind)
    from kesbrdf.io.model_file import load_model
    from kesbrdf.plotting.figures import figure_6

    titles = [ax.get_title() for ax in figure_6(load_model(model), n=15).axes]
    assert any(t.startswith("model (kes-halfdiff, ") for t in titles) and not any("KES," in t for t in titles), titles
    from kesbrdf.plotting.figures import figure_3a, figure_4

    hd = load_model(model)
    legend = [t.get_text() for t in figure_3a(hd, mapping=hd.mappings[0]).axes[0].get_legend().get_texts()]
    assert legend and all(t.endswith("kes-halfdiff model") for t in legend), legend
    polar = figure_4(hd, mapping=hd.mappings[0]).axes[0]
    assert [ln.get_label() for ln in polar.lines if ln.get_gid() == "kes"] == ["kes-halfdiff"]
    # figure 5 reads the (phi, gamma) table: a kes-halfdiff model's tabulated view (issue 19;
    # it used to refuse with "figure 5 supports models of kind 'kes'")
    assert main(["plot", str(model), "--figure", "5", "-o", str(tmp_path / "f5.png")]) == 0
    assert (tmp_path / "f5.png").stat().st_size > 0


def test_fit_says_the_comparisons_reason_once(tmp_path):
    """`kesbrdf fit` printed the comparison's reason twice when it kept the prior: on the
    comparison line and again inside the kind line (found by trying the product).  The
    kind line now points at the comparison line instead."""
    import kesbrdf
    from kesbrdf.io.measurement_csv import write_measurement
    from kesbrdf.measure import planning
    from kesbrdf.references.irawan2012 import Irawan2012

    m = planning.simulate(Irawan2012("silk_charmeuse"), ("paper",), noise=0.02, rng=0)
    meas, model = tmp_path / "silk.csv", tmp_path / "silk.kes.json"
    write_measurement(meas, m)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["fit", str(meas), "-o", str(model)]) == 0
    why = kesbrdf.fit(m)[1].comparison["why"]  # the same comparison (remembered by the rows' content)
    text = err.getvalue()
    assert len(why) > 20 and text.count(why) == 1 and "(the comparison above)" in text
