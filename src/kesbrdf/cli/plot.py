"""``kesbrdf plot MODEL --figure 3a|3b|4|5|6|albedo|all -o OUT``: the paper's figures."""

from __future__ import annotations

from pathlib import Path

from kesbrdf.cli._common import REFERENCES, check_output, stderr

HELP = "Draw the paper's figures (3a, 3b, 4, 5, 6) from a model, a measurement and a reference."

FIGURE_CHOICES = ("3a", "3b", "4", "5", "6", "albedo", "all")


def add_arguments(p):
    p.add_argument("model", help="model file (.kes.json)")
    p.add_argument("--measurement", help="measurement CSV: measured points in Fig. 3 and 4")
    p.add_argument("--reference", metavar="NAME|PATH",
                   help=f"reference BRDF compared in Fig. 6: {', '.join(REFERENCES)}, or an RGL .bsdf / MERL .binary path")
    p.add_argument("--reference-params", metavar="JSON", help="reference parameters as JSON, e.g. '{\"alpha_x\": 0.1}'")
    p.add_argument("--figure", choices=FIGURE_CHOICES, default="all", help="which figure (default all)")
    p.add_argument("-o", "--output", required=True,
                   help="output file (.png, .svg, .pdf) or folder (one file per figure)")
    p.add_argument("--format", choices=("png", "svg", "pdf"), default="png",
                   help="file format inside an output folder (default png)")
    p.add_argument("--channel", help="channel name or index (default: the only one, or the mean)")
    p.add_argument("--mapping", choices=("paper", "deviation", "halfvector", "halfdiff"), default=None,
                   help="mapping used to evaluate the model (default: the model kind's own, deviation for kes)")
    p.add_argument("--gamma-deg", metavar="LIST", default="-60,0",
                   help="signed gamma values of Fig. 4, degrees, comma separated; write "
                        "--gamma-deg=-60,0 when the list starts with a minus (default -60,0)")
    p.add_argument("--dpi", type=int, default=150, help="PNG resolution (default 150)")


def _outputs(args) -> list[tuple[str, Path]]:
    """(figure, path) pairs; checked before any work so a bad -o writes nothing."""
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.plotting.save import FORMATS

    out = Path(args.output)
    names = [f for f in FIGURE_CHOICES if f != "all"] if args.figure == "all" else [args.figure]
    suffix = out.suffix.lower().lstrip(".")
    if suffix and not out.is_dir():
        if suffix not in FORMATS:
            raise KesbrdfError(f"-o {out}: expected a folder or a file ending in .png, .svg or .pdf, got .{suffix}")
        if len(names) > 1:
            raise KesbrdfError(f"-o {out}: expected a folder for --figure all, got a file name")
        return [(names[0], check_output(out))]
    check_output(out, folder=True)
    return [(n, out / f"fig{n}.{args.format}") for n in names]


def _gamma_list(text: str):
    from kesbrdf.errors import KesbrdfError

    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise KesbrdfError(f"--gamma-deg: expected numbers separated by commas, got {text!r}") from None
    if not values or not all(abs(v) < 90 for v in values):  # also refuses nan
        raise KesbrdfError(f"--gamma-deg: expected values in (-90, 90), got {text!r}")
    return values


def _sha256(path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def load_inputs(args):
    """Model, measurement and reference named on the command line (shared with report)."""
    from kesbrdf.cli._common import make_reference
    from kesbrdf.io.model_file import load_model as load

    model = load(args.model)
    measurement = None
    if args.measurement:
        from kesbrdf.io.measurement_csv import read_measurement

        measurement = read_measurement(args.measurement)
    reference = None
    if args.reference:
        reference = make_reference(args.reference, args.reference_params, "--reference-params")
    return model, measurement, reference


def run(args) -> int:
    from kesbrdf.plotting.figures import make_figure
    from kesbrdf.plotting.save import save_figure

    outputs = _outputs(args)
    gamma_deg = _gamma_list(args.gamma_deg)
    if not 10 <= args.dpi <= 1200:
        from kesbrdf.errors import KesbrdfError

        raise KesbrdfError(f"--dpi: expected a resolution in [10, 1200] dots per inch, got {args.dpi}")
    model, measurement, reference = load_inputs(args)
    extra = {"model_file": str(args.model), "model_file_sha256": _sha256(args.model)}
    for name, path in outputs:
        kwargs = {}
        if name in ("3a", "3b", "4", "5", "6"):
            kwargs["channel"] = args.channel
        if name in ("3a", "3b", "4", "6"):
            kwargs["mapping"] = args.mapping
        if name == "4":
            kwargs["gamma_deg"] = gamma_deg
        fig = make_figure(name, model=model, measurement=measurement, reference=reference, **kwargs)
        save_figure(fig, path, record=extra, dpi=args.dpi)
        stderr(f"wrote {path}")
    return 0
