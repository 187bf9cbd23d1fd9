"""``kesbrdf fit MEAS.csv -o MODEL``: build the extended-KES model."""

from __future__ import annotations

from kesbrdf.cli._common import stderr

HELP = "Fit the extended-KES model to a measurement CSV; writes a model file (.kes.json)."


def add_arguments(p):
    p.add_argument("measurement", help="measurement CSV")
    p.add_argument("-o", "--output", required=True, help="model file to write")
    p.add_argument("--orientations", type=int, choices=(3, 4), default=None,
                   help="3 = paper eq. 1-2; 4 = with the 135 deg bias (default when measured)")
    p.add_argument("--fallback", choices=("error", "log"), default="error",
                   help="where K(phi) <= 0 between orientations: fail, or interpolate log rho")
    p.add_argument("--body", default="auto", help="Lambertian body term: auto, none, or a value in 1/sr")
    p.add_argument("--kind", choices=("kes", "kes-halfdiff"), default="kes",
                   help="kes: the paper's table rho(phi, gamma); kes-halfdiff: KES per (theta_h, theta_d) "
                   "for data with several incidence angles per orientation")
    p.add_argument("--warp-deg", type=float, default=None,
                   help="scattered (general-geometry) data: azimuth of the warp in the file's frame; "
                   "default: searched")
    p.add_argument("--interpolation", choices=("kes", "nearest", "linear"), default="kes",
                   help="interpolation over phi (nearest/linear are baselines)")


def run(args) -> int:
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.model import fit

    m = read_measurement(args.measurement)
    for note in m.notes:
        stderr(f"note: {args.measurement}: {note}")
    body = args.body
    if body not in ("auto", "none"):
        try:
            body = float(body)
        except ValueError:
            from kesbrdf.errors import KesbrdfError

            raise KesbrdfError(f"--body: expected auto, none or a number, got {args.body!r}") from None
    if not m.is_in_plane.any():
        # scattered data (e.g. CUReT): fit the KES table + body by least squares
        from kesbrdf.scattered import fit_scattered

        model = fit_scattered(m, warp_deg=args.warp_deg, body=body)
        model.save(args.output)
        p = model.parameters
        stderr(
            f"wrote {args.output}: scattered fit of {len(m)} samples, warp at {p['warp_offset_deg']:.1f} deg "
            f"({p.get('warp_offset_rule', 'given')}), symmetry {p.get('symmetry')}, body {model.body.tolist()}"
        )
        return 0
    if args.kind == "kes-halfdiff":
        from kesbrdf.halfdiff import fit_halfdiff

        model = fit_halfdiff(m, orientations=args.orientations, fallback=args.fallback, body=body)
        model.save(args.output)
        stderr(f"wrote {args.output}: kes-halfdiff, table {tuple(model.table.shape)}, channels {', '.join(model.channels)}")
        return 0
    model = fit(m, orientations=args.orientations, fallback=args.fallback, body=body, interpolation=args.interpolation)
    model.save(args.output)
    d = model.diagnostics
    stderr(
        f"wrote {args.output}: {model.orientations} orientations, {len(model.gamma_nodes)} gamma nodes, "
        f"channels {', '.join(model.channels)}; floored {len(d['floored'])} half-sample(s), "
        f"log fallback at {len(d['fallback_gamma_deg'])} gamma value(s)"
    )
    if "residual_135" in d:
        worst = max(v["max_abs_rel"] for v in d["residual_135"].values())
        stderr(f"135 deg residual of the 3-orientation form: max relative {worst:.3g}")
    return 0
