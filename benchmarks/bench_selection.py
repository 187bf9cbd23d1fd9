"""Does ``kesbrdf.fit(kind="auto")`` keep the model that is best off-sample? (docs/models.md)

For every reference of benchmarks/bench_prior.py (Irawan–Marschner and Sadeghi presets,
anisotropic Ward, Ashikhmin–Shirley, the RGL felt) and the demo's black satin, measured
in the paper protocol with 2 % multiplicative noise (seeded per reference):

* **oracle**: the true off-sample NRMSE (:func:`kesbrdf.validate.compare.metrics`, all
  channels, against the noise-free reference) of ``kes``, the pure ``prior`` and
  ``prior+residual`` fitted to all the samples, on the held-out orientations
  (:data:`kesbrdf.validate.compare.HELD_OUT_DEG`) and the two Fig. 6 hemispheres; ``score``
  is the mean of the three, and the oracle's choice is the candidate with the lowest
  score.  The linear and nearest interpolation baselines are scored too.
* **evidence**: what a rule may use, computed from the noisy samples only:
  :func:`kesbrdf.validate.selection.loo_compare` (per orientation), the mirror discrepancy
  between the two biases and the KES-free interpolation over ψ
  (:func:`kesbrdf.validate.selection.mirror_test`,
  :func:`kesbrdf.validate.selection.orientation_interpolation_loo`).
* **rules**: each rule's choice per reference, agreement with the oracle, and the
  summed score of its choices per family, beside always-``kes`` and the oracle.  A
  rule with a threshold has it chosen leave-one-family-out (the threshold is picked
  on the other families, from a fixed grid, and applied to the held-out family).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent / "src") not in sys.path:
    sys.path.insert(0, str(HERE.parent / "src"))
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from kesbrdf.models.brdf import evaluate  # noqa: E402
from kesbrdf.geometry import spherical_to_cartesian  # noqa: E402
from kesbrdf.measure.gonio import measure  # noqa: E402
from kesbrdf.models.kes import fit as kes_fit  # noqa: E402
from kesbrdf.models.fibre_physics import fit_prior  # noqa: E402
from kesbrdf.models.fibre_prior import FibrePriorModel, ratio_measurement, ratio_table  # noqa: E402
from kesbrdf.validate.selection import choose, loo_compare  # noqa: E402
from kesbrdf.validate.compare import HELD_OUT_DEG, HEMISPHERE_LIGHTS_DEG, hemisphere_directions, metrics  # noqa: E402

#: Multiplicative noise of the simulated measurements (σ = 2 % of the value).
NOISE = 0.02
CANDIDATES = ("kes", "prior", "prior+residual")
CASES = ("held_out", "hemi90", "hemi45")


def references() -> dict:
    """bench_prior's families plus the demo's black satin (its own family)."""
    import bench_prior

    fams = bench_prior.references()
    try:
        from kesbrdf.references.sadeghi2013 import black_satin

        fams["demo"] = {"black_satin": black_satin()}
    except Exception:  # noqa: BLE001
        fams["demo"] = {}
    return fams


def oracle(ref, m) -> dict:
    """{case: {model: NRMSE}} against the noise-free reference, and {model: score}."""
    prior = fit_prior(m)
    models = {
        "kes": kes_fit(m, fallback="log"),
        "prior": FibrePriorModel(prior, None, channels=m.channels),
        "prior+residual": FibrePriorModel(prior, ratio_table(ratio_measurement(prior, m)), channels=m.channels),
        "linear": kes_fit(m, fallback="log", interpolation="linear"),
        "nearest": kes_fit(m, fallback="log", interpolation="nearest"),
    }
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    wr, _, _ = hemisphere_directions()
    wr = wr.reshape(-1, 3)
    cases = {"held_out": (held.wi, held.wr, held.values)}
    for (ti, pi), tag in zip(HEMISPHERE_LIGHTS_DEG, ("hemi90", "hemi45")):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(ti), np.radians(pi)), wr.shape)
        cases[tag] = (wi, wr, np.asarray(ref(wi, wr), float))
    out = {case: {name: metrics(evaluate(mod, wi, wr), truth)["all"]["nrmse"] for name, mod in models.items()}
           for case, (wi, wr, truth) in cases.items()}
    out["score"] = {name: float(np.mean([out[c][name] for c in CASES])) for name in models}
    out["best"] = min(CANDIDATES, key=out["score"].get)
    return out


def evidence(m) -> dict:
    """Everything a rule may look at: computed from the measurement alone."""
    loo = loo_compare(m)
    return {"loo": loo["orientations"], "median_biases": loo["median_biases"],
            "interpolation": loo["interpolation"], "median_all": loo["median_all"], "mirror": loo["mirror"]}


# -- rules: evidence -> candidate --------------------------------------------------------

def _med(ev, cand, psis):
    vals = [ev["loo"][p][cand] for p in psis if p in ev["loo"] and cand in ev["loo"][p]]
    return float(np.median(vals)) if vals else float("nan")


def _as_result(ev, z_limit=None):
    """The evidence as a :func:`kesbrdf.validate.selection.loo_compare` result, optionally with
    another limit on the mirror test's z."""
    mirror = dict(ev["mirror"])
    if z_limit is not None and mirror.get("z") is not None:
        mirror["symmetric"] = mirror["z"] <= z_limit
    return {"orientations": ev["loo"], "median_biases": ev["median_biases"], "interpolation": ev["interpolation"],
            "median_all": ev["median_all"], "mirror": mirror}


def rule_bias_loo(ev, z_limit=None):
    """The rule before this study: lowest median NRMSE on the two held-out biases."""
    med = ev["median_biases"]
    best = min(med, key=med.get)
    return best if med[best] < med["kes"] else "kes"


def rule_adequacy_always(ev, z_limit=None):
    """:func:`kesbrdf.validate.selection.choose` with every fabric taken as mirror-symmetric: the
    interpolation baseline only, kes's bias error never a comparison."""
    return choose(_as_result(ev, z_limit=np.inf))[0]


def rule_adequacy_0_90(ev, z_limit=None):
    """Prior's LOO at warp and weft against interpolation over ψ there, on every fabric."""
    if _med(ev, "prior", ("0", "90")) < float(np.median([ev["interpolation"][p] for p in ("0", "90")])):
        return "prior+residual"
    return "kes"


def rule_choose(ev, z_limit=None):
    """:func:`kesbrdf.validate.selection.choose` (mirror test, then adequacy): the rule adopted."""
    return choose(_as_result(ev, z_limit))[0]


RULES = {
    "bias_loo (before)": (rule_bias_loo, False),
    "adequacy_0_90, every fabric": (rule_adequacy_0_90, False),
    "choose without kes's bias error": (rule_adequacy_always, False),
    "choose (adopted; mirror z <= 2)": (rule_choose, False),
    "choose, z limit leave-one-family-out": (rule_choose, True),
}
#: Limits on the mirror test's z tried leave-one-family-out.
TAU_GRID = (1.0, 1.5, 2.0, 3.0, 5.0)


def _score_rule(rows, rule, tau):
    return sum(r["oracle"]["score"][rule(r["evidence"], tau)] for r in rows)


def evaluate_rules(rows_by_family: dict) -> dict:
    """Per rule and family: agreement with the oracle, summed score of the choices."""
    fams = [f for f, rows in rows_by_family.items() if rows]
    out = {}
    for name, (rule, has_tau) in RULES.items():
        per, taus = {}, {}
        for fam in fams:
            tau = None
            if has_tau:  # leave this family out, pick the threshold on the others
                others = [r for f in fams if f != fam for r in rows_by_family[f]]
                tau = min(TAU_GRID, key=lambda t: (_score_rule(others, rule, t), t))
                taus[fam] = tau
            rows = rows_by_family[fam]
            choices = [rule(r["evidence"], tau) for r in rows]
            per[fam] = {
                "choices": choices,
                "agree": int(sum(c == r["oracle"]["best"] for c, r in zip(choices, rows))),
                "n": len(rows),
                "score": float(sum(r["oracle"]["score"][c] for c, r in zip(choices, rows))),
            }
        out[name] = {"families": per, "agree": sum(p["agree"] for p in per.values()),
                     "n": sum(p["n"] for p in per.values()),
                     "score": float(sum(p["score"] for p in per.values()))}
        if has_tau:
            out[name]["tau_leave_one_family_out"] = taus
    ref = {}
    for label, pick in (("always_kes", lambda r: "kes"), ("oracle", lambda r: r["oracle"]["best"])):
        per = {fam: float(sum(r["oracle"]["score"][pick(r)] for r in rows_by_family[fam])) for fam in fams}
        ref[label] = {"families": per, "score": float(sum(per.values())),
                      "agree": int(sum(pick(r) == r["oracle"]["best"] for f in fams for r in rows_by_family[f]))}
    out.update(ref)
    return out


def run(families=None) -> dict:
    """Oracle table, evidence and rule evaluation over every reference."""
    rows_by_family, table = {}, {}
    for k, (fam, refs) in enumerate(references().items()):
        if families is not None and fam not in families:
            continue
        rows_by_family[fam] = []
        for j, (name, ref) in enumerate(refs.items()):
            m = measure(ref, noise=NOISE, rng=1000 * k + j)
            row = {"oracle": oracle(ref, m), "evidence": evidence(m)}
            row["before"] = rule_bias_loo(row["evidence"])
            row["choice"] = rule_choose(row["evidence"])
            rows_by_family[fam].append(row)
            table[f"{fam}/{name}"] = row
            print(f"  {fam}/{name}: oracle {row['oracle']['best']}, before {row['before']}, now {row['choice']}",
                  file=sys.stderr, flush=True)
    result = {"noise": NOISE, "references": table, "rules": evaluate_rules(rows_by_family)}
    result["markdown"] = markdown(result)
    return result


def markdown(result: dict) -> str:
    """The per-reference oracle table and the per-family rule table (docs/decisions.md)."""
    lines = ["| reference | kes | prior | prior+res | linear | mirror z | before | now | oracle |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, r in result["references"].items():
        s = r["oracle"]["score"]
        lines.append(f"| {name} | {s['kes']:.3f} | {s['prior']:.3f} | {s['prior+residual']:.3f} | {s['linear']:.3f} "
                     f"| {r['evidence']['mirror'].get('z', float('nan')):.2f} | {r['before']} | {r['choice']} "
                     f"| {r['oracle']['best']} |")
    lines += ["", "| rule | agrees | " + " | ".join(next(iter(result["rules"].values()))["families"]) + " | total |",
              "|---|---|" + "---|" * (len(next(iter(result["rules"].values()))["families"]) + 1)]
    for name, r in result["rules"].items():
        fams = r["families"]
        vals = [fams[f] if isinstance(fams[f], float) else fams[f]["score"] for f in fams]
        agree = f"{r['agree']}/{r.get('n', len(result['references']))}"
        lines.append(f"| {name} | {agree} | " + " | ".join(f"{v:.3f}" for v in vals) + f" | {r['score']:.3f} |")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    res = run()
    print(res["markdown"])
