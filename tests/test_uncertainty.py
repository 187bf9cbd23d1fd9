"""Per-prediction σ (kesbrdf.validate.uncertainty): eval --uncertainty, validate coverage, calibration."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from kesbrdf.cli.main import main
from kesbrdf.errors import ModelError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.io.measurement_csv import write_measurement
from kesbrdf.io.model_file import load_model as load
from kesbrdf.models.fibre_prior import FibrePriorModel
from kesbrdf.references.irawan2012 import PRESET_NAMES as IRAWAN_PRESETS, Irawan2012
from kesbrdf.references.sadeghi2013 import Sadeghi2013
from kesbrdf.references.ashikhmin_shirley import AshikhminShirley
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.uncertainty import coverage, predict_sigma, within_bands
from kesbrdf.validate.compare import HELD_OUT_DEG, hemisphere_directions

# Calibration of the σ a model FILE carries: fit (Laplace) ⊕ spread to the pure prior
# and to the stored KES table ⊕ the off-support terms scaled by the fabric's misfit to
# the prior (eq. U1, SIGMA_SCALES chosen leave-one-family-out, docs/prior.md §5).
# Measured at 2 % noise, paper protocol, 5° hemisphere grid, truths within 1σ / 2σ:
#                     held-out ψ    hemisphere φ_i = 90°   φ_i = 45°
#   Irawan twill      56 / 94 %     72 / 95 %              67 / 93 %
#   Sadeghi satin     56 / 72 %     76 / 97 %              75 / 94 %
#   Ward 0.1/0.3      74 / 99 %     76 / 99 %              71 / 100 %
# Bounds, per reference and case (n = 348–1044 held-out samples, 324 hemisphere
# directions).  Sampling: the binomial sd of a coverage fraction at n ≈ 300 is
# ≤ √(0.25/300) ≈ 0.03, but neighbouring directions share their errors (the error is a
# smooth function of direction), so the effective n is tens, not hundreds: at n_eff ≈ 25
# the 2-sd interval is ±0.19 around 0.68 and ±0.09 around 0.95.  Model slack: one set
# of scales serves every family; fitted without the family tested it gives family means
# of 0.40–0.86 at 1σ and 0.58–1.0 at 2σ (docs/prior.md §5), and single references
# spread wider (satin's held-out orientations, 72 % at 2σ, is the worst we measured;
# the calibration keeps every reference's held-out 2σ at ≥ 71 %).
# Accepted: 1σ in [0.45, 0.98] (not badly overconfident; not every truth inside 1σ, which
# would mean a uselessly wide band), 2σ ≥ 0.70 (at most 30 % misses where 5 % is ideal;
# satin's 72 % is the binding case, honest rather than tuned away).
MIN_1SIGMA, MAX_1SIGMA = 0.45, 0.98
MIN_2SIGMA = 0.70
TRAIN_MIN_2SIGMA = 0.95
# The band stays informative: median σ of ln f below 0.5 (a factor 1.65) on the held-out
# orientations, where the data pins the model down.
MAX_MEDIAN_SIGMA_LOG = 0.5
# Coarse hemisphere: 10° viewer grid (≈ 330 directions) keeps the test fast.
HEMI_STEP_DEG = 10.0
# The eval CSV writes repr(float): values round-trip exactly.
CSV_RTOL = 1e-12

REFERENCES = {
    "irawan_twill": Irawan2012("cotton_twill"),
    "sadeghi_satin": Sadeghi2013("satin"),
    "ward_0.1_0.3": AnisotropicWard(0.1, 0.3, 0.3, 0.05),
}


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """{name: (measurement at 2 % noise, fitted model, its saved file)}, fitted once."""
    d = tmp_path_factory.mktemp("cal")
    out = {}
    for name, ref in REFERENCES.items():
        m = measure(ref, noise=0.02, noise_floor=1e-4, rng=3)
        model = FibrePriorModel.fit_measurement(m)
        model.save(d / f"{name}.kes.json")
        out[name] = (m, model, d / f"{name}.kes.json")
    return out


@pytest.mark.parametrize("name", list(REFERENCES))
def test_file_sigma_calibration(name, fitted):
    ref = REFERENCES[name]
    m, _, path = fitted[name]
    model = load(path)
    assert model.kes is not None and model.support is not None
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    f, s, sl = predict_sigma(model, held.wi, held.wr)
    case = coverage(f, sl, held.values)
    assert MIN_1SIGMA <= case["within_1sigma"] <= MAX_1SIGMA, case
    assert case["within_2sigma"] >= MIN_2SIGMA, case
    assert case["median_sigma_log"] < MAX_MEDIAN_SIGMA_LOG, case
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    for phi_i in (90.0, 45.0):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(phi_i)), wr.shape)
        f, s, sl = predict_sigma(model, wi, wr)
        case = coverage(f, sl, ref(wi, wr))
        assert MIN_1SIGMA <= case["within_1sigma"] <= MAX_1SIGMA, (phi_i, case)
        assert case["within_2sigma"] >= MIN_2SIGMA, (phi_i, case)
    # the training samples: the residual reproduces them, only noise separates them
    f, s, sl = predict_sigma(model, m.wi, m.wr)
    assert coverage(f, sl, m.values)["within_2sigma"] >= TRAIN_MIN_2SIGMA
    # σ in 1/sr is f·σ_ln f
    np.testing.assert_allclose(s, f * sl, rtol=1e-12)


def test_file_sigma_equals_in_memory_sigma(fitted):
    """The file holds everything the σ needs: the loaded model gives the fitted model's σ."""
    _, model, path = fitted["irawan_twill"]
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(90.0)), wr.shape)
    a = predict_sigma(model, wi, wr)[2]
    b = predict_sigma(load(path), wi, wr)[2]
    # the file stores float64 arrays exactly; only JSON float text of the prior's
    # parameters (repr, exact) and evaluation order could differ
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12)


def test_old_payload_without_kes_candidate_reads_and_says_so(fitted, tmp_path):
    """A file written before the KES candidate and the support were stored still loads; its
    σ lacks those two terms (so it is narrower off the slice) and its diagnostics say so."""
    _, _, path = fitted["sadeghi_satin"]
    doc = json.loads(path.read_text())
    del doc["kes_candidate"], doc["support"]
    (tmp_path / "old.kes.json").write_text(json.dumps(doc))
    new, old = load(path), load(tmp_path / "old.kes.json")
    assert old.kes is None and old.support is None
    assert "KES candidate" in old.diagnostics["uncertainty"]
    assert "uncertainty" not in new.diagnostics
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(90.0)), wr.shape)
    f_new, _, s_new = predict_sigma(new, wi, wr)
    f_old, _, s_old = predict_sigma(old, wi, wr)
    np.testing.assert_allclose(f_old, f_new, rtol=1e-12)  # same prediction
    # without the KES candidate and the off-support term the band is narrower off the
    # slice (the mean spread over fewer candidates can be larger at single points) and
    # covers fewer truths (satin, φ_i = 90°: 2σ coverage 0.85 before, 0.92 after)
    assert np.median(s_old) < np.median(s_new)
    truth = Sadeghi2013("satin")(wi, wr)
    assert coverage(f_old, s_old, truth)["within_2sigma"] < coverage(f_new, s_new, truth)["within_2sigma"]


def test_support_distance_is_zero_on_the_measured_slice():
    from kesbrdf.models.fibre_prior import support_distance

    support = {"theta_d_deg": [45.0, 45.0], "gamma_max_deg": 60.0}
    # in-plane pair on the paper's line θ_i + θ_r = 90°: θ_d = 45°, γ = 30° (inside)
    wi = spherical_to_cartesian(np.radians(30.0), 0.0)[None]
    wr = spherical_to_cartesian(np.radians(60.0), np.pi)[None]
    assert support_distance(support, wi, wr)[0] == pytest.approx(0.0, abs=1e-7)
    # retro-reflection: θ_d = 0, γ = 2θ = 60° (at the γ edge): d = 45° in radians
    wr = spherical_to_cartesian(np.radians(30.0), 0.0)[None]
    assert support_distance(support, wi, wr)[0] == pytest.approx(np.radians(45.0), rel=1e-6)


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
    # a kes file as written before the σ summary (no "sigma" field): it refuses σ
    doc = json.loads((d / "k.kes.json").read_text())
    del doc["sigma"]
    (d / "k_old.kes.json").write_text(json.dumps(doc))
    pairs = d / "pairs.csv"
    pairs.write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\n30,90,30,270\n60,180,30,0\n30,45,85,200\n89,10,89,190\n")
    return d, m


def test_eval_uncertainty_columns(prior_files, tmp_path):
    from kesbrdf.io.model_file import load_model as load

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


def test_eval_uncertainty_on_old_kes_file_is_a_one_line_error(prior_files, tmp_path, capsys):
    """A kes file without the σ summary (written before it) loads and refuses σ in one line."""
    d, _ = prior_files
    rc = main(["eval", str(d / "k_old.kes.json"), "--pairs", str(d / "pairs.csv"), "-o", str(tmp_path / "o.csv"),
               "--uncertainty"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "carries no uncertainty" in err and "fibre-prior" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o.csv").exists()
    with pytest.raises(ModelError):
        from kesbrdf.io.model_file import load_model as load

        predict_sigma(load(d / "k_old.kes.json"), np.array([[0, 0, 1.0]]), np.array([[0, 0, 1.0]]))
    # the kes file written now carries its σ (eq. K1 of kesbrdf.models.kes_sigma)
    assert main(["eval", str(d / "k.kes.json"), "--pairs", str(d / "pairs.csv"), "-o", str(tmp_path / "k.csv"),
                 "--uncertainty"]) == 0


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
    assert main(["validate", str(d / "k_old.kes.json"), str(d / "meas.csv")]) == 0
    assert "holds no sigma" in capsys.readouterr().out
    assert main(["validate", str(d / "k.kes.json"), str(d / "meas.csv")]) == 0
    assert "within 1 sigma" in capsys.readouterr().out


def test_bad_support_is_one_error_naming_the_file_once(fitted, tmp_path):
    """A corrupted `support` is a one-line ModelError with the file named once and the value shown."""
    from kesbrdf.errors import KesbrdfError

    _, _, path = fitted["sadeghi_satin"]
    doc = json.loads(path.read_text())
    doc["support"]["gamma_max_deg"] = float("nan")
    bad = tmp_path / "bad.kes.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(KesbrdfError) as exc:
        load(bad)
    text = str(exc.value)
    assert text.count("bad.kes.json") == 1 and "support" in text and "nan" in text.lower()
    assert "\n" not in text


# --- Issue 20: σ coverage inside its bands, per family --------------------------------
# The σ (eq. U1, SIGMA_SCALES) was calibrated by benchmarks/bench_calibrate_sigma.py on five
# families; this checks two of them against the bands (COVERAGE_BANDS: within 1σ
# 60–76 %, within 2σ 90–98 %), each case a family mean over its references like the
# benchmark.  Ward (both references, ~4 s to fit each) is the fast test; the six
# Irawan–Marschner presets (~45 s of fits) are the `slow` one.  At the frozen scales the
# benchmark (5° hemispheres) gives Ward [1σ, 2σ] = held-out [0.70, 0.98], φ_i = 90°
# [0.73, 0.99], 45° [0.68, 1.00]; Irawan [0.71, 0.93], [0.60, 0.90], [0.58, 0.89].  The
# other three families are outside the bands (docs/prior.md §5).
# Tolerance FAMILY_BAND_TOL = 0.05 each side of each band: (a) the hemispheres here are
# the 10° grid (324 viewers) where the benchmark uses 5° (1296), which moves the family
# means by ≤ 0.01 (measured at the frozen scales: 0.006 at most); (b) the errors are smooth in
# direction, so of n ≈ 300–1000 truths per case only tens to a hundred are independent:
# at n_eff ≈ 100 the binomial sd of a fraction near 0.7 is 0.046.  A σ scaled 3× (or
# ÷ 3) moves the coverage by 0.2–0.5 and fails (test below).
FAMILY_BAND_TOL = 0.05
FAMILIES = {
    "ward": {"ward_0.1_0.3": AnisotropicWard(0.1, 0.3, 0.3, 0.05),
             "ward_0.25_0.08": AnisotropicWard(0.25, 0.08, [0.2, 0.15, 0.1], 0.1)},
    "irawan2012": {n: Irawan2012(n) for n in IRAWAN_PRESETS},
}


def _cases(fitted, fam, d) -> list:
    """[(case, f, σ_ln f, truth)] over the references of ``fam``, from saved model files."""
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    rows = []
    for name, ref in FAMILIES[fam].items():
        key = "irawan_twill" if name == "cotton_twill" else name
        if key in fitted:
            path = fitted[key][2]
        else:
            path = d / f"{name}.kes.json"
            FibrePriorModel.fit_measurement(measure(ref, noise=0.02, noise_floor=1e-4, rng=3)).save(path)
        model = load(path)
        held = measure(ref, orientations_deg=HELD_OUT_DEG)
        rows.append(("held_out",) + tuple(predict_sigma(model, held.wi, held.wr)[::2]) + (held.values,))
        for phi_i in (90.0, 45.0):
            wi = np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(phi_i)), wr.shape)
            rows.append((f"hemi{phi_i:g}",) + tuple(predict_sigma(model, wi, wr)[::2]) + (ref(wi, wr),))
    return rows


@pytest.fixture(scope="module")
def ward_cases(fitted, tmp_path_factory):
    return _cases(fitted, "ward", tmp_path_factory.mktemp("ward"))


def _family_coverage(rows, sigma_factor=1.0) -> dict:
    """{case: (mean within 1σ, mean within 2σ)} over a family's references."""
    out = {}
    for case in ("held_out", "hemi90", "hemi45"):
        cov = [coverage(f, sigma_factor * sl, t) for c, f, sl, t in rows if c == case]
        out[case] = (np.mean([c["within_1sigma"] for c in cov]), np.mean([c["within_2sigma"] for c in cov]))
    return out


def _assert_in_bands(family, rows):
    for case, (c1, c2) in _family_coverage(rows).items():
        assert within_bands(c1, c2, tol=FAMILY_BAND_TOL), (family, case, c1, c2)


def test_sigma_coverage_inside_its_bands_ward(ward_cases):
    """Issue 20: within 1σ 60–76 %, within 2σ 90–98 % of held-out truths, on the held-out
    orientations and both hemispheres (± FAMILY_BAND_TOL), Ward family."""
    _assert_in_bands("ward", ward_cases)


@pytest.mark.slow
def test_sigma_coverage_inside_its_bands_irawan(fitted, tmp_path):
    """The same bands on the six Irawan–Marschner presets (slow: five more fits)."""
    _assert_in_bands("irawan2012", _cases(fitted, "irawan2012", tmp_path))


@pytest.mark.parametrize("factor", [3.0, 1 / 3.0])
def test_uncalibrated_sigma_fails_the_bands(factor, ward_cases):
    """The band check can fail: the same σ scaled 3× (too wide) or ÷ 3 (too narrow)
    leaves the bands on some case."""
    cov = _family_coverage(ward_cases, factor)
    assert not all(within_bands(c1, c2, tol=FAMILY_BAND_TOL) for c1, c2 in cov.values()), (factor, cov)
    # and the calibrated σ of the same cases is inside (the test above, one line here)
    assert all(within_bands(c1, c2, tol=FAMILY_BAND_TOL) for c1, c2 in _family_coverage(ward_cases).values())


# s of eq. U3 (the fabric's misfit to the prior) measured by bench_calibrate_sigma:
# Irawan twill 0.019 (the prior's own family: only the 2 % noise, RMS ≈ 0.02), Ward
# 0.1/0.3 0.16, Sadeghi satin 0.41.  Bounds with room for the noise draw and the prior's
# fit: twill < 0.05, Ward > 0.10, satin > 0.25 (and the order).
MISFIT_IN_FAMILY_MAX, MISFIT_WARD_MIN, MISFIT_SATIN_MIN = 0.05, 0.10, 0.25


def test_misfit_level_orders_the_fabrics_and_scales_the_off_support_sigma(fitted):
    from kesbrdf.models.fibre_prior import misfit_level, off_support_variance

    models = {name: load(fitted[name][2]) for name in REFERENCES}
    s = {name: misfit_level(m) for name, m in models.items()}
    assert s["irawan_twill"] < MISFIT_IN_FAMILY_MAX < MISFIT_WARD_MIN < s["ward_0.1_0.3"], s
    assert s["sadeghi_satin"] > MISFIT_SATIN_MIN and s["sadeghi_satin"] > s["ward_0.1_0.3"], s
    # the file holds everything s needs: the fitted model gives the same number
    assert misfit_level(fitted["sadeghi_satin"][1]) == pytest.approx(s["sadeghi_satin"], rel=1e-9)
    # off the slice (retro-reflection, θ_d = 0) and between orientations (ψ = 22.5°) the
    # off-support variance grows with s; on the measured slice it is zero
    wi = spherical_to_cartesian(np.radians([40.0, 40.0, 30.0]), np.radians([90.0, 22.5, 0.0]))
    wr = spherical_to_cartesian(np.radians([40.0, 50.0, 60.0]), np.radians([90.0, 202.5, 180.0]))
    v = {name: off_support_variance(m, wi, wr) for name, m in models.items()}
    assert np.all(v["irawan_twill"][:2] < v["ward_0.1_0.3"][:2]) and np.all(v["ward_0.1_0.3"][:2] < v["sadeghi_satin"][:2]), v
    assert all(x[2] == pytest.approx(0.0, abs=1e-12) for x in v.values()), v
