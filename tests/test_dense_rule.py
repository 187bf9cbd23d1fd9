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
    # (both medians, or the KES branch settled early: fibre-coord's lower bound, dense_orientation_loo(decide=True))
    assert rd.fitter in ("fibre-coord", DENSE_KES_BRANCH)
    assert len(rd.comparison["median_all"]) == 2 or (rd.fitter == DENSE_KES_BRANCH and rd.comparison["skipped"])
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
