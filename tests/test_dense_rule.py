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
    assert rd.fitter in ("fibre-coord", DENSE_KES_BRANCH) and len(rd.comparison["median_all"]) == 2
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

    m = measure(AnisotropicWard(0.15, 0.3, 0.2, 0.1), protocol="dense", step_deg=15)
    model, report = fit(m)
    med = report.comparison["median_all"]
    assert med["interp(psi)"] < med["fibre-coord"]
    assert model.kind == DENSE_KES_BRANCH
    assert "median of the four orientations" in report.comparison_summary()
