"""``kesbrdf plan``: expected hemisphere error of candidate protocols, and what to add."""

from __future__ import annotations

import json
from pathlib import Path

from kesbrdf.cli._common import REFERENCES, check_output, make_reference, stderr

HELP = "Plan a measurement: expected hemisphere error of candidate protocols within a sample budget."


def add_arguments(p):
    p.add_argument("--reference", action="append", default=[], metavar="NAME",
                   help=f"reference BRDF to plan for (repeatable): {', '.join(REFERENCES)}, or an RGL .bsdf / MERL "
                   ".binary path")
    p.add_argument("--model", action="append", default=[], metavar="MODEL",
                   help="fitted model file used as the truth (repeatable)")
    p.add_argument("--library", action="store_true",
                   help="plan for every built-in reference but the irawan-* presets (name those with --reference: "
                        "a woven truth the prior is kept for costs minutes)")
    p.add_argument("--budget", type=int, default=240, help="largest number of samples (default 240)")
    p.add_argument("--noise", type=float, default=0.0, help="relative measurement noise (std / value)")
    p.add_argument("--kind", default="auto",
                   help="model kind each protocol is fitted with: auto (the default: kesbrdf fit's rule, "
                        "comparison with the prior included) or a kind such as fibre-prior (~2-7 s a fit)")
    p.add_argument("-o", "--output", required=True,
                   help="plan as JSON: the scores, and the sample geometries (theta, phi, psi, wi, wr) of every scored "
                        "protocol and of the recommended one; kesbrdf simulate --plan measures them")
    p.add_argument("--plot", help="also draw the plan (.png, .svg or .pdf): error against samples, names in a legend table")


def dumps(obj, level: int = 0) -> str:
    """JSON of a plan, indented, with every list of numbers or strings on one line (a
    sample row is one line of plan.json, so the file reads as a table)."""
    pad, inner = " " * level, " " * (level + 1)
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        items = [f"{inner}{json.dumps(str(k))}: {dumps(v, level + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + f"\n{pad}}}"
    if isinstance(obj, (list, tuple)):
        if all(not isinstance(v, (dict, list, tuple)) for v in obj):
            return json.dumps(list(obj))
        return "[\n" + ",\n".join(f"{inner}{dumps(v, level + 1)}" for v in obj) + f"\n{pad}]"
    return json.dumps(obj)


def run(args) -> int:
    from kesbrdf._atomic import write_text
    from kesbrdf.errors import KesbrdfError

    out = Path(args.output)
    if out.suffix.lower() != ".json":
        raise KesbrdfError(f"-o {out}: expected a file ending in .json, got {out.suffix or 'no suffix'}")
    if args.plot and Path(args.plot).suffix.lower() not in (".png", ".svg", ".pdf"):
        raise KesbrdfError(f"--plot {args.plot}: expected a file ending in .png, .svg or .pdf")
    check_output(out, (".json",))
    if args.plot:
        check_output(args.plot, (".png", ".svg", ".pdf"), "--plot")
    truths = {}
    from kesbrdf.references.registry import IRAWAN_REFERENCES

    library = tuple(r for r in REFERENCES if r not in IRAWAN_REFERENCES)  # the set --library planned before them
    for name in (library if args.library else args.reference):
        truths[name] = make_reference(name)
    for path in args.model:
        from kesbrdf.models.brdf import evaluate
        from kesbrdf.io.model_file import load_model as load

        model = load(path)

        def as_truth(wi, wr, model=model):
            return evaluate(model, wi, wr)

        as_truth.channels = tuple(model.channels)
        truths[Path(path).name] = as_truth
    if not truths:
        raise KesbrdfError("plan: expected --reference NAME, --model FILE or --library, got none")
    from kesbrdf.measure.planning import fitter, plan

    fit = fitter(args.kind)
    result = plan(truths, budget=args.budget, noise=args.noise, fit=fit, progress=lambda msg: stderr(f"plan: {msg}"))
    doc = result.to_dict()
    write_text(out, dumps(doc) + "\n")
    for name, p in doc["protocols"].items():
        if p.get("over_budget"):
            stderr(f"  {name:20s} {p['n_samples']:4d} samples  over budget")
        else:
            unused = p["n_samples"] - p.get("rows_used", p["n_samples"])
            note = f"; {unused} not used by the fit" if unused > 0 else ""
            stderr(f"  {name:20s} {p['n_samples']:4d} samples  expected hemisphere NRMSE {p['median']:.3f}  "
                   f"({', '.join(p['kinds'])}{note})")
    rec = doc["recommendation"]
    if len(rec) > 1:
        stderr("recommended additions: " + ", ".join(f"{r['add']} (-> {r['median']:.3f} at {r['n_samples']})" for r in rec[1:]))
    elif rec:
        stderr(f"recommended: no addition within the budget improves on {rec[0]['groups']} ({rec[0]['median']:.3f})")
    if "recommended" in doc:
        stderr(f"the recommended protocol's {doc['recommended']['n_samples']} sample geometries are in {out} "
               "('recommended', 'samples'); measure them, or simulate them with kesbrdf simulate --plan "
               f"{out} (docs/planning.md, 'Carrying out a plan')")
    if args.plot:
        from kesbrdf.plotting.planning import figure_plan
        from kesbrdf.plotting.save import save_figure

        save_figure(figure_plan(doc), args.plot, record={"plan": {"budget": args.budget, "truths": doc["truths"]}})
        stderr(f"wrote {args.plot}")
    stderr(f"wrote {out}")
    return 0
