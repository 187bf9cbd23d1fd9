"""``kesbrdf fit INPUT -o MODEL``: build a model with :func:`kesbrdf.fit`.

INPUT is a measurement CSV, a CUReT ``abrdf.dat`` (``--sample``), an RGL ``.bsdf`` or a
MERL ``.binary`` (sampled at ``--protocol``'s geometries), read by
:func:`kesbrdf.io.sources.read_source`.

The kind is chosen automatically (the one that uses every row, docs/models.md) unless
``--kind`` names one; the choice, the rows used and any warnings go to stderr.  Only
the options the user gave are passed on, and one that does not apply to the chosen
kind is an error.
"""

from __future__ import annotations

from kesbrdf.cli._common import check_output, stderr

HELP = ("Fit a model to a measurement CSV, CUReT abrdf.dat, RGL .bsdf or MERL .binary (kind chosen from "
        "the data); writes a model file (.kes.json).")


def add_arguments(p):
    from kesbrdf.cli._protocol import add_protocol_arguments
    from kesbrdf.models.base import known_fitters

    p.add_argument("measurement", metavar="INPUT",
                   help="measurement CSV, CUReT abrdf.dat (table.txt beside it; --sample), RGL .bsdf or MERL "
                   ".binary (recognised by content and ending; docs/formats.md)")
    p.add_argument("-o", "--output", required=True, help="model file to write")
    p.add_argument("--kind", choices=("auto",) + known_fitters(), default="auto",
                   help="auto (default): the kind that uses every row; kes: the paper's table rho(phi, gamma); "
                   "kes-halfdiff: KES per (theta_h, theta_d) for several incidence angles per orientation; "
                   "fibre-prior: the woven-cloth prior times a KES residual (docs/prior.md); "
                   "scattered: a kes table fitted to general geometries")
    p.add_argument("--orientations", type=int, choices=(3, 4), default=None,
                   help="3 = paper eq. 1-2; 4 = with the 135 deg bias (default when measured)")
    p.add_argument("--strict", action="store_true",
                   help="fail where K(phi) <= 0 between orientations instead of the recorded log fallback")
    p.add_argument("--fallback", choices=("error", "log"), default=None,
                   help="where K(phi) <= 0 between orientations (default log, with a warning; "
                   "--strict is --fallback error)")
    p.add_argument("--body", default=None,
                   help="body term: auto (kes: a Fresnel-like c g(cos theta_i) g(cos theta_r) when the samples show one, "
                        "else Lambertian; docs/models.md), lambertian, none, or a Lambertian value in 1/sr")
    p.add_argument("--warp-deg", type=float, default=None,
                   help="scattered (general-geometry) data: azimuth of the warp in the file's frame; "
                   "default: searched")
    p.add_argument("--interpolation", choices=("kes", "nearest", "linear"), default=None,
                   help="kes kind: interpolation over phi (nearest/linear are baselines)")
    p.add_argument("--no-compare", action="store_true",
                   help="auto: skip the held-out comparison with the woven-cloth prior (fibre-prior)")
    p.add_argument("--sample", default=None,
                   help="CUReT input: the sample, by number (42) or fabric name (corduroy)")
    add_protocol_arguments(p, default=None, what="at which an RGL .bsdf / MERL .binary is sampled (default paper)")


def _options(args) -> dict:
    """The options the user gave, converted; nothing else (library defaults apply)."""
    from kesbrdf.errors import KesbrdfError

    options = {}
    if args.orientations is not None:
        options["orientations"] = args.orientations
    if args.fallback is not None:
        options["fallback"] = args.fallback
    if args.body is not None:
        body = args.body
        if body not in ("auto", "lambertian", "none"):
            try:
                body = float(body)
            except ValueError:
                raise KesbrdfError(f"--body: expected auto, lambertian, none or a number, got {args.body!r}") from None
        options["body"] = body
    if args.warp_deg is not None:
        options["warp_deg"] = args.warp_deg
    if args.interpolation is not None:
        options["interpolation"] = args.interpolation
    return options


def run(args) -> int:
    import kesbrdf
    from kesbrdf.cli._protocol import orientations
    from kesbrdf.io.sources import read_source

    check_output(args.output)
    options = _options(args)
    m = read_source(args.measurement, sample=args.sample, protocol=args.protocol, step_deg=args.step_deg,
                    orientations_deg=orientations(args.orientations_deg))
    for note in m.notes:
        stderr(f"note: {args.measurement}: {note}")
    model, report = kesbrdf.fit(m, kind=args.kind, strict=args.strict, compare=not args.no_compare, **options)
    if report.comparison:
        stderr(f"{args.measurement}: {report.comparison_summary()}")
    stderr(f"{args.measurement}: {report.summary(after_comparison=bool(report.comparison))}")
    for w in report.warnings:
        stderr(f"warning: {w}")
    model.save(args.output)
    stderr(f"wrote {args.output}: {_describe(model, report)}")
    d = model.diagnostics
    if "residual_135" in d:
        worst = max(v["max_abs_rel"] for v in d["residual_135"].values())
        stderr(f"135 deg residual of the 3-orientation form: max relative {worst:.3g}")
    return 0


def _describe(model, report) -> str:
    """The model's own one line, and what the fit floored or fell back on (when recorded)."""
    d = model.diagnostics if isinstance(model.diagnostics, dict) else {}
    extra = ""
    if "floored" in d or "fallback_gamma_deg" in d:
        extra = (f"; floored {len(d.get('floored', []))} half-sample(s), "
                 f"log fallback at {len(d.get('fallback_gamma_deg', []))} gamma value(s)")
    return model.describe() + extra
