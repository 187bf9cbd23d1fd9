"""``kesbrdf report MODEL [--measurement MEAS.csv] -o REPORT.html``: one self-contained HTML report."""

from __future__ import annotations

from pathlib import Path

from kesbrdf.cli._common import REFERENCES, check_output, stderr

HELP = "Write one self-contained HTML report: the paper's figures, metrics, diagnostics, provenance."


def add_arguments(p):
    p.add_argument("model", help="model file (.kes.json)")
    p.add_argument("--measurement", help="measurement CSV: metrics, leave-one-orientation-out, measured points")
    p.add_argument("--reference", metavar="NAME|PATH",
                   help=f"reference BRDF: Fig. 6 and KES against the baselines; {', '.join(REFERENCES)}, or an RGL "
                   ".bsdf / MERL .binary path")
    p.add_argument("--reference-params", metavar="JSON", help="reference parameters as JSON")
    p.add_argument("-o", "--output", required=True, help="report file (.html)")
    p.add_argument("--title", default=None, help="report title (default: from the model's sample name)")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector", "halfdiff"), default=None,
                   help="mapping used to evaluate the model (default: the model kind's own, deviation for kes)")
    p.add_argument("--figures-dir", help="also save each figure as a PNG in this folder")


def run(args) -> int:
    from kesbrdf.cli.plot import load_inputs
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.plotting.report import ReportInputs, collect, write_report

    out = Path(args.output)
    if out.suffix.lower() not in (".html", ".htm"):
        raise KesbrdfError(f"-o {out}: expected a file ending in .html, got {out.suffix or 'no suffix'!r}")
    if args.figures_dir and Path(args.figures_dir).exists() and not Path(args.figures_dir).is_dir():
        raise KesbrdfError(f"--figures-dir {args.figures_dir}: expected a folder, got an existing file")
    check_output(out, (".html", ".htm"))
    if args.figures_dir:
        check_output(args.figures_dir, flag="--figures-dir", folder=True)
    model, measurement, reference = load_inputs(args)
    stderr("computing metrics and diagnostics ...")
    metrics, diagnostics = collect(model, measurement, reference, mapping=args.mapping)
    sample = (model.input_info or {}).get("sample") or (model.input_info or {}).get("name") or Path(args.model).name
    title = args.title or f"kesbrdf report: {sample}"
    stderr("drawing figures ...")
    options = {name: {"mapping": args.mapping} for name in ("3a", "3b", "4", "6")}
    write_report(out, ReportInputs(model, measurement=measurement, reference=reference, metrics=metrics,
                                   diagnostics=diagnostics, title=title, figure_dir=args.figures_dir,
                                   figure_options=options))
    stderr(f"wrote {out}")
    return 0
