"""The demo's prior part (issue 9): default vs baselines, the fibre-prior model, a small plan.

Kept out of ``cli/demo.py`` so the shared demo stays a list of steps.  Everything here
costs a few seconds: the prior fits take ~1 s each on 116 samples, the plan fits with
``kesbrdf.fit``'s default rule (its comparison made once, on the paper's rows) for three
protocols and one greedy step.
"""

from __future__ import annotations

from kesbrdf.cli._common import stderr

#: The demo's plan: the paper protocol and two cheap extensions (docs/planning.md).
DEMO_PLAN_PROTOCOLS = ("paper", "paper+out-of-plane", "paper+specular")
#: Greedy candidates tried in the demo (one step each: a few seconds).
DEMO_PLAN_CANDIDATES = ("oop:30", "specular:36")
#: Fig. 6 lights of the demo plan (the paper's two): the plan stays a few seconds.
DEMO_PLAN_LIGHTS_DEG = ((30.0, 90.0), (30.0, 45.0))


def default_vs_baselines(m, reference, model, report, say) -> dict:
    """Fit the candidates and the baselines, compare them, print one verdict per case.

    Returns ``{"table": compare_models(...), "verdicts": [...], "headline": one line,
    "prior_model": model}``.
    """
    from kesbrdf.validate.baselines import compare_models, verdicts
    from kesbrdf.models.kes import fit as kes_fit
    from kesbrdf.models.fibre_prior import FibrePriorModel

    say("default model vs baselines (nearest, linear over phi) and the fibre-prior candidates")
    prior_res = FibrePriorModel.fit_measurement(m)
    prior_pure = FibrePriorModel.fit_measurement(m, residual=False)
    default = f"default ({model.kind})"
    models = {default: model, "kes": kes_fit(m), "prior": prior_pure, "prior+residual": prior_res}
    baselines = {name: kes_fit(m, interpolation=name) for name in ("linear", "nearest")}
    table = compare_models(m, reference, models, baselines, default)
    lines = verdicts(table)
    head = headline(table, model, report)
    stderr(f"    {head}")
    for line in lines:
        stderr(f"    {line}")
    comparison = report.comparison_summary() if report is not None else ""
    if comparison:
        stderr(f"    kesbrdf.fit's own choice: {comparison}")
    return {"table": table, "verdicts": lines, "headline": head, "prior_model": prior_res}


def headline(table, model, report) -> str:
    """One plain line: does the default beat linear and nearest in every case, and which model it is."""
    d = table["default"]
    cases = table["cases"]
    lost = {case: [b for b in table["baselines"] if b in row and row[d]["rmse"] >= row[b]["rmse"]]
            for case, row in cases.items()}
    lost = {case: bases for case, bases in lost.items() if bases}
    chosen = model.kind
    if report is not None and report.comparison:
        chosen += f", kept by kesbrdf.fit: {report.comparison.get('kept')}"
    if not lost:
        return f"verdict: the default model ({chosen}) beats linear and nearest interpolation in all {len(cases)} cases"
    where = "; ".join(f"{case}: {' and '.join(bases)}" for case, bases in lost.items())
    return (f"verdict: the default model ({chosen}) does NOT beat both baselines in {len(lost)} of "
            f"{len(cases)} cases (not beaten: {where}); the reason is on that case's line below")


def small_plan(reference, say) -> dict:
    """:func:`kesbrdf.measure.planning.plan` for the demo's reference on three protocols."""
    from kesbrdf.measure.planning import PROTOCOLS, plan

    say("plan: expected hemisphere error of the paper protocol and two extensions")
    result = plan({"black satin": reference}, budget=200,
                  protocols={k: PROTOCOLS[k] for k in DEMO_PLAN_PROTOCOLS},
                  candidates=DEMO_PLAN_CANDIDATES,
                  lights_deg=DEMO_PLAN_LIGHTS_DEG)
    d = result.to_dict()
    scored = {k: p for k, p in d["protocols"].items() if not p.get("over_budget")}
    for name, p in scored.items():
        unused = p["n_samples"] - p.get("rows_used", p["n_samples"])
        # set aside by the subset rule or the prior's extras check (docs/models.md, "More rows never predict worse")
        note = f"; {unused} samples not used: they would not improve it" if unused > 0 else ""
        stderr(f"    {name}: {p['n_samples']} samples, expected hemisphere NRMSE {p['median']:.3f} "
               f"(fit: {', '.join(p['kinds'])}{note})")
    base = scored.get("paper")
    worse = [k for k, p in scored.items() if base and k != "paper" and p["median"] > base["median"]]
    if worse:
        # say why more samples score worse instead of letting the numbers look like a bug
        stderr(f"    note: {', '.join(worse)} score worse than the paper protocol alone: the model fitted to "
               "the larger set (kind in brackets) extrapolates worse over the hemisphere, so more samples do "
               "not mean a better model here; `kesbrdf plan --kind fibre-prior` plans for the prior instead "
               "(docs/planning.md)")
    return d
