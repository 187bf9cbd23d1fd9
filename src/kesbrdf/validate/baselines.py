"""The default model against the interpolation baselines, with a plain verdict per case.

:func:`kesbrdf.validate.compare.compare_reference` fits KES and its baselines (nearest
measured orientation, linear interpolation over φ) from one measurement and scores
them on held-out orientations and the Fig. 6 hemispheres.  :func:`compare_models` adds
any further models (the default ``kesbrdf.fit`` choice, the fibre-prior candidates)
to the same cases, and :func:`verdicts` says in one line per case whether the default
beats each baseline — and when it does not, where its error is (docs/prior.md §6).
"""

from __future__ import annotations

import numpy as np

from kesbrdf.models.brdf import evaluate
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.validate.compare import HELD_OUT_DEG, HEMISPHERE_LIGHTS_DEG, hemisphere_directions, metrics

__all__ = ["compare_models", "verdicts", "BASELINES", "RIM_THETA_DEG", "HIGHLIGHT_QUANTILE"]

#: The baselines the default must beat (issue 9).
BASELINES = ("linear", "nearest")
#: Viewing (or light) polar angle above which a direction counts as "the rim".
RIM_THETA_DEG = 70.0
#: Truths above this quantile count as "the highlight".
HIGHLIGHT_QUANTILE = 0.95


def _cases(m, reference, held_out_deg, lights_deg):
    """(case name, wi, wr, truth) of the held-out orientations and each Fig. 6 light."""
    protocol = "dense" if '"protocol": "dense"' in str(m.metadata.get("generator", "")) else "paper"
    held = measure(reference, protocol=protocol, orientations_deg=held_out_deg)
    yield "held_out_orientations", held.wi, held.wr, held.values
    wr, _, _ = hemisphere_directions()
    wr = wr.reshape(-1, 3)
    for theta_i, phi_i in lights_deg:
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(theta_i), np.radians(phi_i)), wr.shape)
        yield f"hemisphere_theta_i{theta_i:g}_phi_i{phi_i:g}", wi, wr, np.asarray(reference(wi, wr), float)


def _where(pred, truth, wi, wr) -> dict:
    """Shares of the squared error in the highlight and at the rim."""
    err2 = np.sum((np.asarray(pred) - truth) ** 2, axis=-1)
    total = max(float(err2.sum()), np.finfo(float).tiny)
    t = np.sum(truth, axis=-1)
    hi = t >= np.quantile(t, HIGHLIGHT_QUANTILE)
    rim = np.maximum(np.degrees(np.arccos(np.clip(wr[:, 2], -1, 1))),
                     np.degrees(np.arccos(np.clip(wi[:, 2], -1, 1)))) >= RIM_THETA_DEG
    return {"highlight_share": float(err2[hi].sum() / total), "rim_share": float(err2[rim].sum() / total)}


def compare_models(m, reference, models: dict, baselines: dict, default: str,
                   held_out_deg=HELD_OUT_DEG, lights_deg=HEMISPHERE_LIGHTS_DEG) -> dict:
    """Metrics of every model and baseline on the held-out cases.

    Parameters
    ----------
    m : Measurement
        What the models were fitted to (its protocol picks the held-out one).
    reference : callable f(wi, wr) -> (..., C)
        The truth.
    models, baselines : dict name -> model
        Models evaluated with :func:`kesbrdf.models.brdf.evaluate` in their own mapping.
    default : str
        The name (in ``models``) of the default model, judged by :func:`verdicts`.

    Returns
    -------
    dict
        ``{"default": name, "cases": {case: {name: {"rmse", "nrmse", "log_rmse"}}},
        "where": {case: {"highlight_share", "rim_share"}}}`` (the error shares of the
        default's squared error).
    """
    everything = {**models, **baselines}
    out = {"default": default, "baselines": list(baselines), "cases": {}, "where": {}}
    for case, wi, wr, truth in _cases(m, reference, held_out_deg, lights_deg):
        row = {}
        for name, mod in everything.items():
            pred = evaluate(mod, wi, wr)
            a = metrics(pred, truth)["all"]
            row[name] = {k: a[k] for k in ("rmse", "nrmse", "log_rmse")}
            if name == default:
                out["where"][case] = _where(pred, truth, wi, wr)
        out["cases"][case] = row
    return out


def verdicts(result: dict) -> list[str]:
    """One line per case: does the default beat each baseline on RMSE, and if not, why.

    "Beats" means a strictly lower RMSE (1/sr) than the baseline on that case.  The
    reason of a loss is where the default's squared error lies: the highlight (the
    brightest 5 % of truths) or grazing angles (θ_i or θ_r ≥ 70°), whichever holds more
    of it; the line also names the other models that do beat every baseline there.
    """
    lines = []
    d = result["default"]
    tiny = np.finfo(float).tiny
    for case, row in result["cases"].items():
        bases = [b for b in result.get("baselines", BASELINES) if b in row]
        a = row[d]["rmse"]
        won = [b for b in bases if a < row[b]["rmse"]]
        lost = [b for b in bases if b not in won]
        parts = [f"{b} {row[b]['rmse']:.4g} (ratio {a / max(row[b]['rmse'], tiny):.2f})" for b in bases]
        head = f"{case}: {d} RMSE {a:.4g} vs " + ", ".join(parts)
        if not lost:
            lines.append(f"{head}: beats {' and '.join(bases)}")
            continue
        w = result.get("where", {}).get(case, {})
        hs, rs = w.get("highlight_share", float("nan")), w.get("rim_share", float("nan"))
        if hs >= rs:
            why = f"{hs:.0%} of its squared error is in the highlight (brightest 5% of truths), the narrow streak the baselines interpolate directly from the measured peaks"
        else:
            why = f"{rs:.0%} of its squared error is at grazing angles (theta_i or theta_r >= {RIM_THETA_DEG:g} deg), far from the measured samples near the specular line"
        better = [f"{n} {r['rmse']:.4g}" for n, r in row.items()
                  if n != d and n not in bases and all(r["rmse"] < row[b]["rmse"] for b in bases)]
        tail = f"; beating all baselines here: {', '.join(better)}" if better else ""
        verdict = f"beats {' and '.join(won)} but does not beat {' or '.join(lost)}" if won else f"does not beat {' or '.join(lost)}"
        lines.append(f"{head}: {verdict}; {why}{tail}")
    return lines
