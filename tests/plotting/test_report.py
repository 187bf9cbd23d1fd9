"""kesbrdf.plotting.report: one self-contained HTML file with figures, metrics,
diagnostics and provenance, rendered from plain dicts."""

import re
from html.parser import HTMLParser

import numpy as np
import pytest

from kesbrdf.plotting.report import REPORT_FIGURES, ReportInputs, _highlights, build_report, collect, write_report

#: The model reproduces its in-plane input samples to round-off (docs/method.md, "From the table to a BRDF"); f_r is O(1)/sr.
ROUND_TRIP_RMSE = 1e-12

METRICS = {
    "round_trip": {"mapping": "deviation", "n": 116,
                   "metrics": {"R": {"rmse": 0.0123456, "nrmse": 0.5, "log_rmse": 0.25, "max_abs": 0.75},
                               "all": {"rmse": 1.5e-17, "nrmse": 2e-16, "log_rmse": 3e-16, "max_abs": 4e-17}}},
    "leave_one_orientation_out": {"0": {"possible": False, "reason": "KES needs <warp> & weft"},
                                  "45": {"possible": True, "metrics": {"value": {"rmse": 0.0424242}}}},
    "reference": {"ratio_kes_to": {"nearest": {"held_out": 0.3125, "hemisphere": 0.8125},
                                   "linear": {"held_out": 0.4375, "hemisphere": 0.9375}}},
    "long": list(np.linspace(0.0, 1.0, 50)),
}
DIAGNOSTICS = {
    "reciprocity_error": 3.25e-16,
    "albedo": {"theta_i_deg": [0.0, 40.0], "phi_i_deg": [0.0, 90.0],
               "values": [[[0.5], [1.25]], [[0.75], [0.875]]], "max": [1.25],
               "above_one": [{"theta_i_deg": 0.0, "phi_i_deg": 90.0, "albedo": [1.25]}]},
    "kes": {"fallback_gamma_deg": [], "floored": 2, "residual_135": {"value": {"max_abs_rel": 0.0625}}},
}


class _Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.urls, self.tags = [], [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        for key, value in attrs:
            if key in ("src", "href") and value:
                self.urls.append(value)
        if tag == "img":
            self.imgs.append(dict(attrs))


def _parse(text):
    c = _Collector()
    c.feed(text)
    return c


@pytest.fixture(scope="module")
def report_text(satin_model, satin_measurement, satin_ref, tmp_path_factory):
    path = tmp_path_factory.mktemp("rep") / "report.html"
    write_report(path, ReportInputs(satin_model, satin_measurement, satin_ref, metrics=METRICS, diagnostics=DIAGNOSTICS,
                                    title="Test <report>", figure_options={"6": {"n": 31}, "3b": {"n_gamma": 9, "n_psi": 5}},
                                    dpi=40))
    assert [p.name for p in path.parent.iterdir()] == ["report.html"]  # one file, nothing else
    return path.read_text(encoding="utf-8")


def test_report_is_self_contained(report_text):
    c = _parse(report_text)
    assert c.urls, "expected embedded images"
    assert all(u.startswith("data:image/png;base64,") for u in c.urls)
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", report_text)
    assert "<link" not in report_text and "<script" not in report_text


def test_report_contains_every_figure(report_text):
    c = _parse(report_text)
    assert len(c.imgs) == len(REPORT_FIGURES)  # 3a, 3b, 4, 5, 6 and the albedo map
    for name in REPORT_FIGURES:
        assert f'id="fig-{name}"' in report_text


def test_report_shows_the_metric_values(report_text):
    for text in ("0.01235", "1.5e-17", "0.04242", "0.3125", "0.8125", "0.4375", "0.9375", "3.25e-16", "0.0625"):
        assert text in report_text
    assert "<h3>leave_one_orientation_out</h3>" in report_text
    assert "KES needs &lt;warp&gt; &amp; weft" in report_text  # escaped
    assert "<title>Test &lt;report&gt;</title>" in report_text
    assert "n = 50, min 0, max 1" in report_text  # long list summarised


def test_report_flags_albedo_above_one(report_text):
    flagged = re.findall(r'class="flag">([^<]*)<', report_text)
    assert "1.25" in flagged and "0.875" not in flagged


def test_report_has_provenance(report_text, satin_model):
    from kesbrdf._version import __version__

    assert "<h2 id=provenance>" in report_text
    assert satin_model.input_info["sha256"] in report_text
    assert f"kesbrdf {__version__}" in report_text


def test_missing_inputs_become_notes(satin_measurement):
    text = build_report(ReportInputs(measurement=satin_measurement, metrics={"a": 1}, figures=("3a", "4"), dpi=30))
    assert len(_parse(text).imgs) == 1
    assert "Figure 4 not drawn: figure 4: expected a model, got none" in text


def test_figure_dir_gets_the_figures(satin_model, tmp_path):
    write_report(tmp_path / "r.html", ReportInputs(satin_model, figures=("5",), figure_dir=tmp_path / "figs", dpi=30))
    assert (tmp_path / "figs" / "fig5.png").read_bytes()[:4] == b"\x89PNG"


def test_collect_uses_validation_and_diagnostics(satin_model, satin_measurement, satin_ref):
    metrics, diagnostics = collect(satin_model, satin_measurement, satin_ref)
    assert set(metrics) == {"round_trip", "leave_one_orientation_out", "reference"}
    assert metrics["round_trip"]["metrics"]["value"]["rmse"] < ROUND_TRIP_RMSE
    assert "reciprocity_error" in diagnostics and "albedo" in diagnostics
    only = collect(satin_model)
    assert only[0] == {}


def test_summary_collects_key_numbers(report_text):
    summary = report_text[report_text.index("<h2 id=summary>"):report_text.index("<h2 id=inputs>")]
    assert "RMSE ratio KES / nearest: held_out" in summary and "0.3125" in summary
    assert "reciprocity error" in summary and "3.25e-16" in summary
    assert re.search(r"albedo, max per channel</td><td[^>]*>.*1\.25", summary)
    assert "incident directions with albedo &gt; 1</td><td>1<" in summary


def test_report_names_its_model_at_the_top(satin_model, satin_measurement):
    """Issue 19: the report says which model it is about (kind, content hash) and why the
    fit chose it, before anything else, and the hash is the model's content hash."""
    import kesbrdf
    from kesbrdf.pipeline import model_sha256

    model, fit_report = kesbrdf.fit(satin_measurement, kind="kes")
    text = build_report(ReportInputs(model, figures=(), notes=["renders skipped: a one-line reason"]))
    head = text[: text.index("<h2 id=inputs>")]
    digest = model_sha256(model)
    assert len(digest) == 64 and f"<td class=txt>{digest}</td>" in head
    assert "<td class=txt>kes</td>" in head and f"<td class=txt>{fit_report.reason}</td>" in head
    assert "renders skipped: a one-line reason" in head
    # a different model (another table) has another hash; equal content, equal hash
    assert model_sha256(satin_model) != digest or np.array_equal(satin_model.table, model.table)
    twin = kesbrdf.fit(satin_measurement, kind="kes")[0]
    assert model_sha256(twin) == digest


def test_summary_says_which_rows_the_left_out_orientation_scores():
    """Issue from the new-user trial: a model fitted with extras had its "ψ = 45° left out"
    scored on every row at 45°; the summary now names the incidence-line rows it scores
    and the rows it leaves out, and scores those rows only."""
    from kesbrdf.measure import planning
    from kesbrdf.models.kes import fit
    from kesbrdf.references.sadeghi2013 import Sadeghi2013

    m = planning.simulate(Sadeghi2013(preset="satin"), ("paper", "line:30"))
    metrics, diagnostics = collect(fit(m), m)
    summary = {k: v for k, v in _highlights(metrics, diagnostics).items() if "left out" in k}
    assert set(summary) == {
        f"KES interpolation (eq. 1–2), ψ = {held}° left out, its 29 rows on θ_i + θ_r = 90° "
        f"(14 other row(s) at ψ = {held}° not scored): nrmse" for held in ("45", "135")}
    assert all(v < 1e-9 for v in summary.values())  # all rows scored gave 0.074
