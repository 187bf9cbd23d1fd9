"""Protocol planning (kesbrdf.measure.planning): sample groups, expected error, greedy plan."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.measure import planning
from kesbrdf.models.brdf import evaluate
from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.models.kes import fit
from kesbrdf.references.ward import AnisotropicWard

#: Geometry identities are exact up to float rounding of trig functions.
GEOMETRY_TOL = 1e-12
#: A model measured in the paper protocol and refitted from those samples is the same
#: table (the round trip of docs/method.md, "From the table to a BRDF"), so its hemisphere error is at round-off level; the
#: bound allows the γ-grid resampling of the refit (linear in q on the same nodes).
SELF_CONSISTENCY_NRMSE = 1e-6


def _ward():
    return AnisotropicWard(0.12, 0.3, rho_d=[0.25, 0.2, 0.15], rho_s=0.15)


@pytest.mark.parametrize("name, size", [("paper", 116), ("dense", 900), ("specular:36", 4), ("line:30", 60), ("oop:60", 4)])
def test_group_sizes(name, size):
    assert len(planning.group_geometry(name)) == size


@pytest.mark.parametrize("bad", ["banana", "specular:90", "line:-5", "oop:x", "specular:nan"])
def test_unknown_group_is_a_one_line_error(bad):
    with pytest.raises(KesbrdfError, match="sample group"):
        planning.group_geometry(bad)


def test_specular_group_is_the_mirror_at_difference_angle_theta():
    g = planning.group_geometry("specular:36")
    wi = spherical_to_cartesian(g.theta_i, g.phi_i)
    wr = spherical_to_cartesian(g.theta_r, g.phi_r)
    h = wi + wr
    assert np.allclose(h[:, :2], 0.0, atol=GEOMETRY_TOL)  # half vector = normal
    theta_d = 0.5 * np.arccos(np.sum(wi * wr, axis=1))
    assert np.allclose(np.degrees(theta_d), 36.0, atol=1e-9)


def test_out_of_plane_group_is_not_in_plane():
    g = planning.group_geometry("oop:30")
    assert np.all(np.isnan(g.psi))
    dphi = np.mod(g.phi_r - g.phi_i, 2 * np.pi)
    assert np.allclose(dphi, 1.5 * np.pi, atol=GEOMETRY_TOL)


def test_shared_samples_are_kept_once():
    assert planning.protocol_size(("paper", "paper")) == 116
    # specular:45 lies on the paper line (θ_i = θ_r = 45°): 4 of its samples are shared
    assert planning.protocol_size(("paper", "specular:45")) == 116


def test_simulated_values_are_the_truth_at_the_samples():
    ref = _ward()
    m = planning.simulate(ref, ("paper", "oop:30"))
    assert len(m) == 120
    assert np.allclose(m.values, ref(m.wi, m.wr), rtol=1e-12)
    assert m.is_in_plane.sum() == 116


def test_model_as_truth_round_trips_in_the_paper_protocol():
    model = fit(measure(_ward()))

    def truth(wi, wr):
        return evaluate(model, wi, wr)

    truth.channels = model.channels
    t = planning._Truth("model", truth, planning.PLAN_LIGHTS_DEG, planning.PLAN_GRID_STEP_DEG)
    res = planning.expected_error([t], ("paper",))
    assert res["n_samples"] == 116
    assert res["median"] < SELF_CONSISTENCY_NRMSE


def test_plan_respects_budget_and_greedy_never_gets_worse():
    # in-plane candidates only: their fits are the fast KES kinds (out-of-plane ones need the scattered fit)
    res = planning.plan({"ward": _ward()}, budget=124, candidates=("specular:36", "specular:60", "line:30"),
                        protocols={"paper": ("paper",), "dense": ("dense",)})
    doc = res.to_dict()
    assert doc["protocols"]["dense"]["over_budget"] is True
    assert doc["protocols"]["paper"]["n_samples"] == 116
    rec = doc["recommendation"]
    assert rec[0]["groups"] == ["paper"]
    assert all(r["n_samples"] <= 124 for r in rec)
    medians = [r["median"] for r in rec]
    assert all(b <= a for a, b in zip(medians, medians[1:]))
    assert all(r["add"] != "line:30" for r in rec[1:])  # 60 samples: over the budget


def test_plan_rejects_bad_budget_and_empty_truths():
    with pytest.raises(KesbrdfError, match="budget"):
        planning.plan({"ward": _ward()}, budget=0)
    with pytest.raises(KesbrdfError, match="at least one"):
        planning.plan({}, budget=100)


def test_fitter_names_the_kind_and_rejects_unknown_ones():
    """`kesbrdf plan --kind`: auto is the default fit; a kind fits that kind; a typo is one line."""
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.measure.gonio import measure
    from kesbrdf.measure.planning import default_fit, fitter
    from kesbrdf.references.ward import AnisotropicWard

    assert fitter("auto") is default_fit
    model = fitter("kes")(measure(AnisotropicWard(0.2, 0.3), protocol="paper"))
    assert model.kind == "kes"
    with pytest.raises(KesbrdfError, match="expected kind one of"):
        fitter("bogus")


# --- more rows never predict worse (issue 20, "The planner agrees with itself") ---------

#: Protocols that hold every sample of the paper protocol and more (planning.PROTOCOLS).
SUPERSETS = ("paper+specular", "paper+line30", "paper+lines", "paper+out-of-plane")
#: A superset may score at most this fraction above the paper protocol: the planner's
#: own threshold (MIN_GAIN, 1 % of the error), below which it treats two protocols as
#: equal.  With the subset rule the fits are the same ``kes`` table on the same 116 rows
#: (observed difference 0); before it the supersets scored 1.1–3.6x the paper protocol.
SUPERSET_TOL = planning.MIN_GAIN
#: The paper's Fig. 6 lights only: two lights keep each case well under a second.
TEST_LIGHTS_DEG = planning.PLAN_LIGHTS_DEG[:2]


def _truths():
    from kesbrdf.measure.demo_data import embedded_reference

    return {"demo black satin": embedded_reference(), "ward 0.12/0.30": AnisotropicWard(0.12, 0.3)}


def _scores(truth_name, protocols, fit=planning.default_fit):
    t = planning._Truth(truth_name, _truths()[truth_name], TEST_LIGHTS_DEG, planning.PLAN_GRID_STEP_DEG)
    return {p: planning.expected_error([t], planning.PROTOCOLS[p], fit=fit) for p in protocols}


@pytest.mark.parametrize("truth", [pytest.param("demo black satin", marks=pytest.mark.slow), "ward 0.12/0.30"])
def test_every_superset_of_the_paper_protocol_scores_no_worse(truth):
    """The default fit never predicts the hemispheres worse from more samples (docs/planning.md).

    The planner fits as ``kesbrdf fit`` does, comparison included: on the demo satin the
    prior is kept, and its extras check (``fitting._extras_check``) turns down the mirror
    samples and the incidence lines that would make it worse (measured before the check:
    + specular 1.49 against 0.89).  Slow there: each superset costs ten prior fits."""
    scores = _scores(truth, ("paper",) + SUPERSETS)
    paper = scores["paper"]["median"]
    for name in SUPERSETS:
        assert scores[name]["median"] <= paper * (1 + SUPERSET_TOL), (truth, name, scores[name]["median"], paper)


@pytest.mark.parametrize("truth", ["demo black satin", "ward 0.12/0.30"])
def test_the_superset_check_fails_under_the_old_rule(truth, monkeypatch):
    """Without the subset rule the fit takes every row (kes-halfdiff on 16 mirror samples
    beside the paper line) and scores worse (measured: satin 1.02 vs 0.75, Ward 0.48 vs 0.13)."""
    from kesbrdf import fitting

    monkeypatch.setattr(fitting, "SUBSET_RULE", False)
    # without the comparison: the subset rule alone is under test (the prior's dense rule
    # would otherwise run on the all-rows kes-halfdiff choice)
    scores = _scores(truth, ("paper", "paper+specular"), fit=lambda m: fitting.fit(m, compare=False)[0])
    assert scores["paper+specular"]["kinds"] == ["kes-halfdiff"]
    assert scores["paper+specular"]["median"] > scores["paper"]["median"] * (1 + SUPERSET_TOL)


# -- carrying out a plan: its sample geometries (docs/planning.md, "Carrying out a plan") --

#: Plan angles are written in degrees rounded to 1e-9° (1.7e-11 rad) and read back;
#: the brief's bound for "the same angles" is 1e-9 rad.
ANGLE_TOL_RAD = 1e-9
#: Direction vectors are written to 12 decimals.
VECTOR_TOL = 1e-11


def test_sample_table_holds_the_rows_the_planner_scores():
    groups = ("paper", "line:30", "specular:36", "oop:30")
    rows = planning.sample_table(groups)
    scored = planning.simulate(_ward(), groups)  # what expected_error fits and scores
    assert len(rows) == len(scored) == 116 + 60 - 4 + 4 + 4  # line:30's θ_r = 60° lies on the paper line
    col = {c: k for k, c in enumerate(planning.SAMPLE_COLUMNS)}
    a = np.radians(np.array([[r[col[c]] for c in ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")] for r in rows]))
    for k, name in enumerate(("theta_i", "phi_i", "theta_r", "phi_r")):
        assert np.max(np.abs(a[:, k] - getattr(scored, name))) < ANGLE_TOL_RAD
    wi = np.array([r[col["wi_x"]:col["wi_z"] + 1] for r in rows])
    wr = np.array([r[col["wr_x"]:col["wr_z"] + 1] for r in rows])
    assert np.max(np.abs(wi - scored.wi)) < VECTOR_TOL and np.max(np.abs(wr - scored.wr)) < VECTOR_TOL
    # ψ is the sample orientation of every row: the light at ψ + 180°; in-plane rows have
    # the viewer at ψ (the measurement CSV's psi_deg), oop rows at ψ + 90°
    psi = np.array([r[col["psi_deg"]] for r in rows])
    phi_i, phi_r = np.degrees(a[:, 1]), np.degrees(a[:, 3])
    assert np.allclose(np.mod(psi + 180.0, 360.0), phi_i, atol=1e-9)
    oop = np.array([r[0] == "oop:30" for r in rows])
    assert oop.sum() == 4 and sorted(psi[oop]) == [0.0, 45.0, 90.0, 135.0]
    assert np.allclose(np.mod(phi_r[oop] - psi[oop], 360.0), 90.0, atol=1e-9)
    assert np.allclose(phi_r[~oop], psi[~oop], atol=1e-9)
    assert np.allclose(np.degrees(scored.psi[~oop]), psi[~oop], atol=1e-9)
    assert [r[0] for r in rows[:116]] == ["paper"] * 116 and rows[116][0] == "line:30"


def test_geometry_from_table_inverts_sample_table():
    groups = ("paper", "oop:30", "oop:60")
    g = planning.geometry_from_table(planning.sample_table(groups))
    want = planning.protocol_samples(groups)
    for name in ("theta_i", "phi_i", "theta_r", "phi_r"):
        assert np.max(np.abs(getattr(g, name) - getattr(want, name))) < ANGLE_TOL_RAD
    assert np.array_equal(np.isnan(g.psi), np.isnan(want.psi)) and np.isnan(g.psi).sum() == 8
    ok = ~np.isnan(want.psi)
    assert np.max(np.abs(g.psi[ok] - want.psi[ok])) < ANGLE_TOL_RAD


def test_plan_json_records_samples_of_every_scored_protocol_and_the_recommendation():
    res = planning.PlanResult(budget=240, truths=["t"],
                              protocols={"paper": {"groups": ["paper"], "over_budget": False, "n_samples": 116},
                                         "dense": {"groups": ["dense"], "over_budget": True, "n_samples": 900}},
                              recommendation=[{"add": None, "groups": ["paper"], "n_samples": 116, "median": 0.5},
                                              {"add": "oop:30", "groups": ["paper", "oop:30"], "n_samples": 120,
                                               "median": 0.4}])
    doc = res.to_dict()
    assert len(doc["protocols"]["paper"]["samples"]) == 116
    assert "samples" not in doc["protocols"]["dense"]  # over budget: not scored, not recorded
    assert doc["recommended"]["groups"] == ["paper", "oop:30"] and len(doc["recommended"]["samples"]) == 120
    assert doc["sample_columns"] == list(planning.SAMPLE_COLUMNS)


def test_parse_groups_is_the_planners_parser():
    assert planning.parse_groups("line:30, oop:30") == ("line:30", "oop:30")
    with pytest.raises(KesbrdfError, match=r"^--extras: sample group: expected paper, dense, specular:T, line:T or "
                                           r"oop:T with 0 <= T < 90 deg, got 'oops:3'$"):
        planning.parse_groups("line:30,oops:3")
    with pytest.raises(KesbrdfError, match="^--extras: expected comma-separated sample groups"):
        planning.parse_groups("line:30,")


def test_single_difference_angle_groups_and_their_pairs():
    """specular:T, oop:T and the paper's line have one ωi·ωr (cos 2T, cos²T and 0: θ_d = 45°
    on every paper sample); line:T and dense have many. Pairs are of the same kind only:
    two in-plane or two out-of-plane groups."""
    for name in ("specular:36", "oop:30", "paper"):
        assert planning.single_difference_angle(name), name
    assert not planning.single_difference_angle("line:30") and not planning.single_difference_angle("dense")
    assert planning.pair_candidates(planning.CANDIDATE_GROUPS) == [
        ("specular:18", "specular:36"), ("specular:18", "specular:60"), ("specular:18", "specular:72"),
        ("specular:36", "specular:60"), ("specular:36", "specular:72"), ("specular:60", "specular:72"),
        ("oop:30", "oop:60")]


def test_greedy_reaches_a_pair_no_single_group_helps():
    """The greedy step stopped when no single group helped, so it never reached oop:30 +
    oop:60, which kesbrdf.fit uses only together (one ωi·ωr each cannot be held out).
    A fit that is exact only with two out-of-plane difference angles, and 2x too bright
    otherwise, makes the planner recommend the pair in one step; the old loop would stop
    at the paper protocol."""
    truth = _ward()

    class Scaled:
        kind = "stub"
        diagnostics = {}

        def __init__(self, scale):
            self.scale = scale

        def evaluate(self, wi, wr, mapping=None):
            return self.scale * np.asarray(truth(wi, wr), float)

    def stub_fit(m):
        out = ~m.is_in_plane
        dots = np.round(np.sum(m.wi[out] * m.wr[out], axis=-1), 9)
        return Scaled(1.0 if len(np.unique(dots)) >= 2 else 2.0)

    res = planning.plan({"ward": truth}, budget=130, candidates=("specular:36", "oop:30", "line:30", "oop:60"),
                        protocols={}, fit=stub_fit)
    rec = res.to_dict()["recommendation"]
    assert [r["add"] for r in rec] == [None, "oop:30 + oop:60"]
    assert rec[0]["median"] >= 1.0  # 2x too bright: NRMSE = RMS(f)/mean(f) >= 1
    assert rec[1]["median"] == pytest.approx(0.0, abs=1e-12) and rec[1]["n_samples"] == 124
    assert res.to_dict()["recommended"]["groups"] == ["paper", "oop:30", "oop:60"]
