"""Per-prediction σ (kesbrdf.uncertainty): eval --uncertainty, validate coverage, calibration."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.errors import ModelError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.gonio import measure
from kesbrdf.io.measurement_csv import write_measurement
from kesbrdf.prior_model import FibrePriorModel
from kesbrdf.references.irawan2012 import Irawan2012
from kesbrdf.references.sadeghi2013 import Sadeghi2013
from kesbrdf.uncertainty import coverage, predict_sigma
from kesbrdf.validation import HELD_OUT_DEG, hemisphere_directions

# Calibration of the σ a model FILE carries (no KES candidate: the file holds none),
# measured at 2 % noise on the paper protocol (docs/prior.md §5, "σ from the file"):
#   Irawan cotton twill: held-out orientations 64 % / 80 % within 1σ / 2σ; Fig. 6
#     hemispheres 13–15 % / 51–61 %  (too narrow at the rim: the two candidates agree
#     there, so the spread term is small where both are wrong);
#   Sadeghi satin: held-out 59 % / 72 %; hemispheres 41–42 % / 72–85 %.
# Bounds: held-out 2σ ≥ 65 % (the lowest measured is 72 %: not badly overconfident on
# the orientations a user would ask about), hemispheres 2σ ≥ 45 % (lowest 51 %: stated
# as overconfident in the docs, guarded against getting worse), the training samples
# ≥ 95 % within 2σ (the residual reproduces them, so only noise separates them), and
# the band informative: median σ of ln f < 0.5 (a factor 1.65).
HELD_MIN_2SIGMA = 0.65
HEMI_MIN_2SIGMA = 0.45
TRAIN_MIN_2SIGMA = 0.95
MAX_MEDIAN_SIGMA_LOG = 0.5
# The eval CSV writes repr(float): values round-trip exactly.
CSV_RTOL = 1e-12


def _fit(ref):
    m = measure(ref, noise=0.02, noise_floor=1e-4, rng=3)
    return m, FibrePriorModel.fit_measurement(m, kinds=("filament", "filament"))


@pytest.mark.parametrize("ref", [Irawan2012("cotton_twill"), Sadeghi2013("satin")], ids=["irawan_twill", "sadeghi_satin"])
def test_file_sigma_calibration(ref):
    m, model = _fit(ref)
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    f, s, sl = predict_sigma(model, held.wi, held.wr)
    case = coverage(f, sl, held.values)
    assert case["within_2sigma"] >= HELD_MIN_2SIGMA, case
    assert case["within_1sigma"] <= case["within_2sigma"]
    assert case["median_sigma_log"] < MAX_MEDIAN_SIGMA_LOG, case
    wr, _, _ = hemisphere_directions(5.0)
    wr = wr.reshape(-1, 3)
    for phi_i in (90.0, 45.0):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(phi_i)), wr.shape)
        f, s, sl = predict_sigma(model, wi, wr)
        case = coverage(f, sl, ref(wi, wr))
        assert case["within_2sigma"] >= HEMI_MIN_2SIGMA, (phi_i, case)
        assert case["median_sigma_log"] < MAX_MEDIAN_SIGMA_LOG, case
    f, s, sl = predict_sigma(model, m.wi, m.wr)
    assert coverage(f, sl, m.values)["within_2sigma"] >= TRAIN_MIN_2SIGMA
    # σ in 1/sr is f·σ_ln f
    np.testing.assert_allclose(s, f * sl, rtol=1e-12)


def test_coverage_counts_values():
    # truths exactly 0.5σ, 1.5σ, 3σ away in log: 1/3 within 1σ, 2/3 within 2σ
    p = np.ones((3, 1))
    sl = np.full((3, 1), 0.1)
    t = np.exp(np.array([[0.05], [-0.15], [0.3]]))
    c = coverage(p, sl, t)
    assert c["within_1sigma"] == pytest.approx(1 / 3)
    assert c["within_2sigma"] == pytest.approx(2 / 3)


@pytest.fixture(scope="module")
def prior_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("unc")
    m = measure(Sadeghi2013("satin"), noise=0.01, noise_floor=1e-4, rng=5)
    write_measurement(d / "meas.csv", m)
    assert main(["fit", str(d / "meas.csv"), "--kind", "fibre-prior", "-o", str(d / "m.kes.json")]) == 0
    assert main(["fit", str(d / "meas.csv"), "--kind", "kes", "-o", str(d / "k.kes.json")]) == 0
    pairs = d / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n30,90,30,270\n60,180,30,0\n30,45,85,200\n89,10,89,190\n")
    return d, m


def test_eval_uncertainty_columns(prior_files, tmp_path):
    from kesbrdf.model import load

    d, _ = prior_files
    out = tmp_path / "o.csv"
    assert main(["eval", str(d / "m.kes.json"), "--pairs", str(d / "pairs.csv"), "-o", str(out), "--uncertainty"]) == 0
    rows = list(csv.DictReader(out.open()))
    model = load(d / "m.kes.json")
    chans = list(model.channels)
    assert list(rows[0])[4:] == chans + [f"sigma_{c}" for c in chans]
    assert len(rows) == 4
    f = np.array([[float(r[c]) for c in chans] for r in rows])
    s = np.array([[float(r[f"sigma_{c}"]) for c in chans] for r in rows])
    assert np.all(np.isfinite(s)) and np.all(s >= 0)
    # σ of ln f is capped at 3 (prior_model.MAX_SIGMA_LOG): σ ≤ 3 f
    assert np.all(s <= 3.0 * f + 1e-300)
    # some σ is non-zero: the prior and the prior+residual differ off the samples
    assert np.any(s > 0)
    # the f column is the model's own prediction (eval without --uncertainty)
    plain = tmp_path / "p.csv"
    assert main(["eval", str(d / "m.kes.json"), "--pairs", str(d / "pairs.csv"), "-o", str(plain)]) == 0
    g = np.array([[float(r[c]) for c in chans] for r in csv.DictReader(plain.open())])
    np.testing.assert_allclose(f, g, rtol=CSV_RTOL)


def test_eval_uncertainty_on_kes_is_a_one_line_error(prior_files, tmp_path, capsys):
    d, _ = prior_files
    rc = main(["eval", str(d / "k.kes.json"), "--pairs", str(d / "pairs.csv"), "-o", str(tmp_path / "o.csv"), "--uncertainty"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "carries no uncertainty" in err and "fibre-prior" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o.csv").exists()
    with pytest.raises(ModelError):
        from kesbrdf.model import load

        predict_sigma(load(d / "k.kes.json"), np.array([[0, 0, 1.0]]), np.array([[0, 0, 1.0]]))


def test_validate_reports_coverage(prior_files, tmp_path, capsys):
    d, _ = prior_files
    js = tmp_path / "v.json"
    assert main(["validate", str(d / "m.kes.json"), str(d / "meas.csv"), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "within 1 sigma" in out
    res = json.loads(js.read_text())["uncertainty"]
    # the measured samples themselves: the residual reproduces them (only the 1 % noise
    # the fit saw separates them), so nearly all lie within 2σ
    assert res["within_2sigma"] >= TRAIN_MIN_2SIGMA
    assert 0 <= res["within_1sigma"] <= res["within_2sigma"] <= 1
    assert main(["validate", str(d / "k.kes.json"), str(d / "meas.csv")]) == 0
    assert "carries no sigma" in capsys.readouterr().out
