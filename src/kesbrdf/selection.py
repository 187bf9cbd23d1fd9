"""Model selection on the user's own data: leave-one-orientation-out comparison of kinds.

``kesbrdf.fit(m, kind="auto")`` first picks the kind that uses every row (docs/models.md);
when the woven-cloth prior (:mod:`kesbrdf.prior_model`) can also use every row, it is
compared with that choice by :func:`loo_compare`, and the better one on held-out
orientations is kept.  The comparison is reported to the user (``FitReport.comparison``).
"""

from __future__ import annotations

import numpy as np

from kesbrdf.measurement import Measurement
from kesbrdf.prior import fit_prior
from kesbrdf.prior_model import FibrePriorModel, ratio_measurement, ratio_table
from kesbrdf.validation import leave_one_orientation_out, mirror_135_to_45

__all__ = ["loo_compare"]


def _nrmse(pred, truth):
    return float(np.sqrt(np.mean((pred - truth) ** 2)) / max(float(np.mean(np.abs(truth))), 1e-300))


def loo_compare(measurement, **fit_options) -> dict:
    """Leave-one-orientation-out NRMSE of ``fibre-prior`` (with and without residual) and ``kes``.

    Each measured orientation is predicted from the others.  ``kes`` can predict only a
    bias (it needs warp and weft; :func:`kesbrdf.validation.leave_one_orientation_out`);
    the pure prior predicts every orientation; prior + residual is reported for the
    biases, with the residual built from the remaining orientations exactly as ``kes``
    builds its table (the other bias mirrored, y → −y).

    Returns
    -------
    dict
        ``{"orientations": {psi_deg: {candidate: nrmse}}, "median": {candidate: median over
        the biases}, "best": candidate with the lowest median on the biases}``.
    """
    

    m = measurement
    psi_deg = np.degrees(np.where(m.is_in_plane, m.psi, np.nan))
    kes_loo = leave_one_orientation_out(m, fallback="log")
    table = {}
    for held in (0.0, 45.0, 90.0, 135.0):
        test_rows = np.abs(psi_deg - held) < 0.5
        if not test_rows.any():
            continue
        test = m.subset(test_rows)
        train = m.subset(~test_rows & np.isfinite(psi_deg))
        prior = fit_prior(train, **fit_options)
        row = {"prior": _nrmse(prior(test.wi, test.wr), test.values)}
        entry = kes_loo.get(f"{held:g}", {})
        if entry.get("possible"):
            row["kes"] = entry["metrics"]["all"]["nrmse"]
            other = 135.0 if held == 45.0 else 45.0
            ratio_m = ratio_measurement(prior, train)
            rpsi = np.degrees(ratio_m.psi)
            keep = (np.abs(rpsi - 0) < 0.5) | (np.abs(rpsi - 90) < 0.5)
            other_rows = np.abs(rpsi - other) < 0.5
            base = ratio_m.subset(keep)
            bias = mirror_135_to_45(ratio_m, other_rows) if held == 45.0 else ratio_m.subset(other_rows)
            rtrain = Measurement.in_plane(np.concatenate([base.psi, bias.psi]), np.concatenate([base.theta_i, bias.theta_i]),
                                          np.concatenate([base.theta_r, bias.theta_r]), np.concatenate([base.values, bias.values]),
                                          channels=m.channels)
            model = FibrePriorModel(prior, ratio_table(rtrain), channels=m.channels)
            if held == 135.0:
                pred = model.evaluate(test.wi, test.wr)
            else:  # the residual was built in the mirrored frame; the prior was not
                flip = np.array([1.0, -1.0, 1.0])
                ratio = model.residual_ratio(test.wr * flip, test.wi * flip)
                pred = prior(test.wi, test.wr) * ratio
            row["prior+residual"] = _nrmse(pred, test.values)
        table[f"{held:g}"] = row
    cands = ("kes", "prior", "prior+residual")
    median = {c: float(np.median([r[c] for r in table.values() if c in r])) for c in cands
              if any(c in r and k in ("45", "135") for k, r in table.items())}
    bias_median = {c: float(np.median([table[k][c] for k in ("45", "135") if k in table and c in table[k]]))
                   for c in cands if any(k in table and c in table[k] for k in ("45", "135"))}
    best = min(bias_median, key=bias_median.get) if bias_median else None
    return {"orientations": table, "median": median, "median_biases": bias_median, "best": best}


#: Folds of :func:`kfold_compare` (the CUReT protocol of docs/prior.md).
K_FOLDS = 5


def _log_rmse(pred, truth) -> float:
    eps = 1e-4 * max(float(np.max(np.abs(truth))), 1e-300)
    return float(np.sqrt(np.mean(np.log((np.maximum(pred, 0) + eps) / (np.maximum(truth, 0) + eps)) ** 2)))


def kfold_compare(measurement, candidates=("scattered", "fibre-prior"), k: int = K_FOLDS, seed: int = 0) -> dict:
    """k-fold cross-validated log RMSE of several fitters on scattered data.

    Rows are split into ``k`` folds at random (seeded, so the choice is repeatable);
    each fitter is fitted on k − 1 folds and predicts the held-out one.  The error is
    the RMS of ln((p + ε)/(t + ε)), ε = 10⁻⁴·max|t| (:func:`kesbrdf.validation.metrics`'s
    ``log_rmse``): real gonio data spans decades, and a relative error weighs them alike.

    Returns
    -------
    dict
        ``{"folds": k, "log_rmse": {candidate: [per fold]}, "median": {candidate: median},
        "best": candidate}``; a candidate whose fit fails on a fold is left out.
    """
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.kinds import fitter_class

    m = measurement
    n = len(m)
    if n < 2 * k:
        raise KesbrdfError(f"{k}-fold comparison: expected at least {2 * k} samples, got {n}")
    fold = np.random.default_rng(seed).permutation(n) % k
    errors: dict = {}
    for name in candidates:
        cls = fitter_class(name)
        per = []
        for j in range(k):
            train, test = m.subset(fold != j), m.subset(fold == j)
            try:
                model = cls.fit_measurement(train)
            except KesbrdfError:
                per = None
                break
            per.append(_log_rmse(model.evaluate(test.wi, test.wr), test.values))
        if per:
            errors[name] = per
    median = {name: float(np.median(v)) for name, v in errors.items()}
    best = min(median, key=median.get) if median else None
    return {"folds": k, "log_rmse": errors, "median": median, "best": best}
