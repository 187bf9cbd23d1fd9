"""Default model vs interpolation baselines (kesbrdf.validate.baselines) and its report sections."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.validate.baselines import compare_models, verdicts
from kesbrdf.measure.gonio import measure
from kesbrdf.models.kes import fit as kes_fit
from kesbrdf.references.sadeghi2013 import Sadeghi2013


def _constructed():
    """A hand-made result: the default wins one case and loses the other two."""
    return {
        "default": "default (kes)",
        "baselines": ["linear", "nearest"],
        "cases": {
            "held_out_orientations": {"default (kes)": {"rmse": 0.066}, "linear": {"rmse": 0.041}, "nearest": {"rmse": 0.080}},
            "hemisphere_a": {"default (kes)": {"rmse": 0.010}, "linear": {"rmse": 0.020}, "nearest": {"rmse": 0.030}},
        },
        "where": {"held_out_orientations": {"highlight_share": 0.1, "rim_share": 0.9},
                  "hemisphere_a": {"highlight_share": 0.7, "rim_share": 0.2}},
    }


def test_verdicts_state_beats_and_does_not_beat():
    lines = verdicts(_constructed())
    assert len(lines) == 2  # one per case
    held, hemi = lines
    assert held.startswith("held_out_orientations:")
    # 0.066 > 0.041 (linear) but < 0.080 (nearest)
    assert "beats nearest but does not beat linear" in held and "(ratio 1.61)" in held
    assert "90% of its squared error is at grazing angles" in held  # the larger share is named
    assert hemi.endswith("beats linear and nearest") and "does not beat" not in hemi


def test_verdicts_tie_is_not_a_win_and_names_the_highlight_and_better_models():
    r = _constructed()
    r["cases"]["hemisphere_a"]["linear"]["rmse"] = 0.010  # equal RMSE: "beats" means strictly lower
    r["cases"]["hemisphere_a"]["prior+residual"] = {"rmse": 0.005}  # beats both baselines
    r["cases"]["hemisphere_a"]["prior"] = {"rmse": 0.015}  # beats nearest only: not named
    line = verdicts(r)[1]
    assert "beats nearest but does not beat linear" in line
    assert "70% of its squared error is in the highlight" in line
    assert line.endswith("beating all baselines here: prior+residual 0.005")


@pytest.fixture(scope="module")
def satin():
    ref = Sadeghi2013("satin")
    m = measure(ref, noise=0.01, noise_floor=1e-4, rng=4)
    return ref, m


def test_compare_models_ranks_a_worse_model_below(satin):
    """The KES model against itself scaled ×2: RMSE grows, the verdict says so."""
    ref, m = satin
    kes = kes_fit(m)

    class Scaled:  # a model twice too bright: must lose to the baselines on every case
        kind, channels, mappings, default_mapping = "scaled", kes.channels, kes.mappings, kes.default_mapping
        n_channels = kes.n_channels

        def evaluate(self, wi, wr, mapping=None):
            from kesbrdf.models.brdf import evaluate
            return 2.0 * evaluate(kes, wi, wr, mapping)

    res = compare_models(m, ref, {"kes": kes, "x2": Scaled()}, {"linear": kes_fit(m, interpolation="linear")}, "x2")
    assert set(res["cases"]) == {"held_out_orientations", "hemisphere_theta_i30_phi_i90", "hemisphere_theta_i30_phi_i45"}
    for case, row in res["cases"].items():
        assert row["x2"]["rmse"] > row["kes"]["rmse"], case
        assert 0 <= res["where"][case]["rim_share"] <= 1 and 0 <= res["where"][case]["highlight_share"] <= 1
    assert all("does not beat linear" in line for line in verdicts(res))


@pytest.mark.slow  # an auto fit, a prior fit and a full report (~9 s): make test-long, which CI runs
def test_report_has_comparison_table_uncertainty_and_planning(satin):
    import kesbrdf
    from kesbrdf.plotting.report import ReportInputs, build_report
    from kesbrdf.models.fibre_prior import FibrePriorModel

    ref, m = satin
    model, report = kesbrdf.fit(m)  # kind=auto: the prior comparison lands in diagnostics
    comp = model.diagnostics["fit_report"]["comparison"]
    if model.kind != "kes":  # the report's main model is a KES table; the demo does the same
        model = kesbrdf.fit(m, kind="kes")[0]
        model.diagnostics["fit_report"] = report.to_dict()
    prior = FibrePriorModel.fit_measurement(m)
    plan = {"budget": 200, "truths": ["satin"], "recommendation": [],
            "protocols": {"paper": {"n_samples": 116, "median": 0.31, "over_budget": False},
                          "paper+out-of-plane": {"n_samples": 124, "median": 0.22, "over_budget": False}}}
    base = compare_models(m, ref, {"default": model}, {"linear": kes_fit(m, interpolation="linear")}, "default")
    base["verdicts"] = verdicts(base)
    text = build_report(ReportInputs(model, m, ref, figures=(), dpi=30, plan=plan, baselines=base, prior_model=prior))
    assert "<h3>Model comparison</h3>" in text
    kept = comp["kept"]
    assert f"kept <b>{kept}</b>" in text
    # the comparison's own numbers are in the table (formatted .4g)
    for c, v in comp["median_biases"].items():
        assert f"{v:.4g}" in text, c
    assert 'id="fig-plan"' in text and "<h3>Protocol planning</h3>" in text
    assert 'id="fig-6-prior-uncertainty"' in text
    assert "Default model vs baselines" in text and base["verdicts"][0] in text.replace("&gt;", ">")
    # without the optional inputs the section keeps only what the model carries
    bare = build_report(ReportInputs(model, m, ref, figures=(), dpi=30))
    assert 'id="fig-plan"' not in bare and 'id="fig-6-prior-uncertainty"' not in bare


def test_uncertainty_figure_values(satin):
    """The σ map is finite and non-negative inside the disk, blank outside."""
    from kesbrdf.plotting.report_prior import figure_uncertainty
    from kesbrdf.models.fibre_prior import FibrePriorModel

    ref, m = satin
    fig = figure_uncertainty(FibrePriorModel.fit_measurement(m), ref, n=21)
    axes = [a for a in fig.axes if a.get_images()]
    assert len(axes) == 8  # 2 lights × (model, truth, log ratio, σ)
    sigma = np.ma.filled(axes[3].get_images()[0].get_array(), np.nan)
    inside = np.isfinite(sigma)
    assert inside.sum() > 0.6 * sigma.size and np.all(sigma[inside] >= 0) and np.all(sigma[inside] <= 3.0)
