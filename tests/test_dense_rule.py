"""The default rule: a dense measurement never predicts worse than the paper's 116 samples (issue 20)."""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.fitting import DENSE_KES_BRANCH, fit
from kesbrdf.measure.gonio import measure
from kesbrdf.validate.lofo import score

#: Allowed excess of the dense hemisphere NRMSE over the paper protocol's.  The same
#: model of the same fabric measured twice (2 % noise, another seed) moves the
#: hemisphere NRMSE by 0.4 % (Sadeghi satin, paper protocol, kes: 0.748-0.751 over
#: five seeds); 10 % is that spread with a margin, far below the excesses the rule
#: removed (Irawan charmeuse 1.9x, Sadeghi linen 2.0x, RGL felt 1.4x: docs/decisions.md).
MARGIN = 0.10


def _refs():
    from kesbrdf.references.irawan2012 import Irawan2012
    from kesbrdf.references.sadeghi2013 import Sadeghi2013

    return {"sadeghi_satin": Sadeghi2013("satin"), "irawan_silk_charmeuse": Irawan2012("silk_charmeuse")}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sadeghi_satin", "irawan_silk_charmeuse"])
def test_dense_is_not_worse_than_paper(name):
    ref = _refs()[name]
    paper = measure(ref, protocol="paper", noise=0.02, rng=11)
    dense = measure(ref, protocol="dense", noise=0.02, rng=12)
    assert len(paper) == 116 and len(dense) == 900
    mp, rp = fit(paper)
    md, rd = fit(dense)
    # the dense rule ran, and kept one of its two branches
    # (both medians, or the folds stopped early, dense_orientation_loo(decide=True): the KES
    # branch settled by fibre-coord's lower bound, or fibre-coord's win by its upper bound,
    # then the difference-angle bands, eq. D2)
    assert rd.fitter in ("fibre-coord", DENSE_KES_BRANCH)
    c = rd.comparison
    assert len(c["median_all"]) == 2 or (c["skipped"] and ("fibre_coord_median_at_least" in c
                                                           or "fibre_coord_median_at_most" in c))
    assert rd.fitter == DENSE_KES_BRANCH or "bands" in c  # fibre-coord only after the second hold-out
    hp = score(mp.evaluate, ref)["hemispheres"]
    hd = score(md.evaluate, ref)["hemispheres"]
    assert hd <= hp * (1 + MARGIN), f"{name}: dense {hd:.3f} ({rd.fitter}) vs paper {hp:.3f} ({rp.fitter})"


def test_dense_rule_needs_all_four_orientations():
    # three orientations: nothing to hold out against interpolation over ψ at every
    # orientation, so the row-based choice stands
    from kesbrdf.references.ward import AnisotropicWard

    m = measure(AnisotropicWard(0.2, 0.3, 0.2, 0.1), protocol="dense", step_deg=15, orientations_deg=(0, 45, 90))
    _, report = fit(m)
    assert report.fitter == "kes-halfdiff" and report.comparison is None


@pytest.mark.slow
def test_dense_rule_keeps_kes_on_a_microfacet_lobe():
    # Ward is no woven cloth: interpolation over ψ predicts a held-out orientation better
    # than the fibre coordinates, and the rule keeps the KES branch (kes-halfdiff)
    from kesbrdf.references.ward import AnisotropicWard
    from kesbrdf.validate.selection import INTERPOLATION

    m = measure(AnisotropicWard(0.15, 0.3, 0.2, 0.1), protocol="dense", step_deg=15)
    model, report = fit(m)
    c = report.comparison
    med = c["median_all"]
    # fibre-coord's median, or its lower bound when the folds stopped early (decide=True)
    assert med["interp(psi)"] <= med.get("fibre-coord", c.get("fibre_coord_median_at_least"))
    assert model.kind == DENSE_KES_BRANCH
    assert "median of the four orientations" in report.comparison_summary()
    # the folds kesbrdf.fit fitted are the full comparison's, number for number
    from kesbrdf.validate.selection import dense_orientation_loo

    full = dense_orientation_loo(m)
    for k, row in c["orientations"].items():
        assert row == {n: v for n, v in full["orientations"][k].items() if n in row}
        assert row[INTERPOLATION] == full["orientations"][k][INTERPOLATION]
    assert full["median_all"]["interp(psi)"] < full["median_all"]["fibre-coord"]


def test_dense_rule_stops_when_the_kes_branch_is_certain():
    """choose_dense keeps fibre-coord only if its median over the four held-out orientations
    is below interpolation's; with the folds not yet fitted at 0 that median is a lower
    bound, and once it is not below interpolation's the KES branch is certain."""
    from kesbrdf.validate.selection import INTERPOLATION, _dense_settled, choose_dense

    interp = {"0": 0.30, "45": 0.20, "90": 0.30, "135": 0.20}  # median 0.25
    table = {k: {INTERPOLATION: v} for k, v in interp.items()}
    table["0"]["fibre-coord"] = 0.9
    assert not _dense_settled(table, "45")  # [0, 0, 0, 0.9]: median 0, nothing settled
    table["45"]["fibre-coord"] = 0.6
    assert _dense_settled(table, "90")  # [0, 0, 0.6, 0.9]: median >= 0.3 >= 0.25
    # whatever the other two give, the median of four is not below the bound
    rng = np.random.default_rng(1)
    assert all(np.median([0.9, 0.6, *x]) >= 0.3 for x in rng.exponential(1.0, size=(200, 2)))
    result = {"orientations": table, "median_all": {INTERPOLATION: 0.25}, "skipped": ["90", "135"],
              "fibre_coord_median_at_least": 0.3}
    kept, why = choose_dense(result, DENSE_KES_BRANCH)
    assert kept == DENSE_KES_BRANCH and "at least 0.300" in why and "90 and 135" in why
    # a failed (absent) or non-finite fold settles nothing: choose_dense says it could not be scored
    table["45"]["fibre-coord"] = float("nan")
    assert not _dense_settled(table, "90")
    del table["45"]["fibre-coord"]
    assert not _dense_settled(table, "90")


# -- the second hold-out, by difference angle (eq. D2) ------------------------------------------

def _orientation_win():
    """A dense_orientation_loo result where fibre-coord wins (0.80 < 0.96, ward_01292's medians)."""
    from kesbrdf.validate.selection import INTERPOLATION

    return {"orientations": {}, "median_all": {"fibre-coord": 0.80, INTERPOLATION: 0.96}}


def test_choose_dense_needs_both_hold_outs():
    """fibre-coord is kept only when it wins the orientation hold-out and the difference-angle
    one (eq. D2); without the second (the old rule) the orientation win alone keeps it."""
    from kesbrdf.validate.selection import choose_dense

    result = _orientation_win()
    assert choose_dense(result, DENSE_KES_BRANCH)[0] == "fibre-coord"  # the old rule
    lose = {"log_sse": {"fibre-coord": 937.7, DENSE_KES_BRANCH: 204.5}, "bands": 4}  # ward_01292's
    kept, why = choose_dense(result, DENSE_KES_BRANCH, lose)
    assert kept == DENSE_KES_BRANCH and "937.7 >= 204.5" in why
    win = {"log_sse": {"fibre-coord": 31.1, DENSE_KES_BRANCH: 273.0}, "bands": 4}  # an Irawan silk charmeuse's
    kept, why = choose_dense(result, DENSE_KES_BRANCH, win)
    assert kept == "fibre-coord" and "31.1 < 273" in why
    # a tie is no evidence for fibre-coord; one band holds nothing out
    tie = {"log_sse": {"fibre-coord": 5.0, DENSE_KES_BRANCH: 5.0}, "bands": 4}
    assert choose_dense(result, DENSE_KES_BRANCH, tie)[0] == DENSE_KES_BRANCH
    one = {"log_sse": {"fibre-coord": 0.0, DENSE_KES_BRANCH: 0.0}, "bands": 1}
    assert choose_dense(result, DENSE_KES_BRANCH, one)[0] == DENSE_KES_BRANCH
    # an orientation loss is not rescued by the bands
    lost = {"orientations": {}, "median_all": {"fibre-coord": 1.0, "interp(psi)": 0.5}}
    assert choose_dense(lost, DENSE_KES_BRANCH, win)[0] == DENSE_KES_BRANCH


def test_difference_angle_bands_are_quartiles_of_wi_dot_wr():
    from kesbrdf.references.ward import AnisotropicWard
    from kesbrdf.validate.selection import difference_angle_bands

    m = measure(AnisotropicWard(0.2, 0.3, 0.2, 0.1), protocol="dense", step_deg=15)
    label = difference_angle_bands(m)
    x = np.round(np.sum(m.wi * m.wr, axis=1), 6)
    assert set(label) == {0, 1, 2, 3}
    # bands are ordered in x and hold a quarter of the distinct values each (+-1 for the rounding of quantiles)
    for g in range(3):
        assert x[label == g].max() < x[label == g + 1].min()
    n = [len(np.unique(x[label == g])) for g in range(4)]
    assert max(n) - min(n) <= 1, n


@pytest.mark.slow
def test_dense_rule_turns_down_fibre_coord_that_loses_by_difference_angle():
    """ward_01292 of the fabric library (seed 0; its dense measurement bit for bit): fibre-coord
    beats interpolation over ψ on held-out orientations, so the old rule kept it, and its
    hemispheres were 0.889 against the paper protocol's 0.381 (docs/decisions.md).  Held out
    by difference angle it loses to kes-halfdiff (eq. D2), and the rule keeps kes-halfdiff."""
    from kesbrdf.references.ward import AnisotropicWard
    from kesbrdf.validate.library import NOISE, noise_seed
    from kesbrdf.validate.selection import INTERPOLATION

    ref = AnisotropicWard(0.41208312231630106, 0.06246048346573006,
                          [0.29484499460620356, 0.13215720517234392, 0.15507114985501402], 0.2175114783337075)
    dense = measure(ref, protocol="dense", noise=NOISE, rng=noise_seed(0, 1292, "dense"))
    model, report = fit(dense)
    c = report.comparison
    assert c["median_all"]["fibre-coord"] < c["median_all"][INTERPOLATION]  # the old rule's fibre-coord win
    s = c["bands"]["log_sse"]
    assert not s["fibre-coord"] < s[DENSE_KES_BRANCH]
    assert report.fitter == DENSE_KES_BRANCH and "difference-angle band" in c["why"]
    assert "difference-angle bands, log SSE" in report.comparison_summary()
    # kes-halfdiff here predicts the hemispheres better than the paper protocol (0.302 < 0.381 measured;
    # the bound is the paper protocol's own score, not a tuned margin)
    assert score(model.evaluate, ref)["hemispheres"] < 0.381


def test_dense_rule_stops_when_fibre_coord_is_certain_to_win_the_orientations():
    """With the folds not yet fitted at +∞ the median of four is an upper bound; once it is
    below interpolation's, fibre-coord wins the orientation hold-out whatever the last fold
    gives (then the difference-angle bands decide, eq. D2)."""
    from kesbrdf.validate.selection import INTERPOLATION, _dense_upper, _dense_won, choose_dense

    interp = {"0": 0.30, "45": 0.20, "90": 0.30, "135": 0.20}  # median 0.25
    table = {k: {INTERPOLATION: v} for k, v in interp.items()}
    table["0"]["fibre-coord"] = 0.10
    table["45"]["fibre-coord"] = 0.05
    assert not _dense_won(table, "90")  # [0.05, 0.1, inf, inf]: median inf
    table["90"]["fibre-coord"] = 0.20
    assert _dense_won(table, "135") and _dense_upper(table) == pytest.approx(0.15)  # [0.05, 0.1, 0.2, inf]
    assert all(np.median([0.10, 0.05, 0.20, x]) <= 0.15 + 1e-12 for x in (0.0, 0.3, 1e9))  # 1e-12: rounding
    result = {"orientations": table, "median_all": {INTERPOLATION: 0.25}, "skipped": ["135"],
              "fibre_coord_median_at_most": 0.15}
    kept, why = choose_dense(result, DENSE_KES_BRANCH)
    assert kept == "fibre-coord" and "at most 0.150" in why
    # ... and the bands can still turn it down
    lose = {"log_sse": {"fibre-coord": 9.0, DENSE_KES_BRANCH: 3.0}, "bands": 4}
    assert choose_dense(result, DENSE_KES_BRANCH, lose)[0] == DENSE_KES_BRANCH
    table["90"]["fibre-coord"] = 0.40  # [0.05, 0.1, 0.4, inf]: bound 0.25, not below 0.25
    assert not _dense_won(table, "135")
