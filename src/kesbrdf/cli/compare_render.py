"""``kesbrdf compare-render --reference NAME``: reference vs fitted model, rendered side by side."""

from __future__ import annotations

from kesbrdf.cli._common import check_output, stderr

HELP = ("Render a reference BRDF and the model fitted from its virtual measurements (by kesbrdf fit's rule, or "
        "--kind) side by side, with a FLIP map.")


def add_arguments(p):
    from kesbrdf.cli.render import add_render_options

    p.add_argument("--reference", required=True, metavar="NAME",
                   help="reference BRDF (ward, satin-ward, ashikhmin-shirley, sadeghi-<preset>, "
                        "sadeghi-black-satin, rgl-felt-white, ...)")
    from kesbrdf.models.base import known_fitters

    p.add_argument("--protocol", choices=("paper", "dense"), default="paper",
                   help="paper: the paper's 116 in-plane samples; dense: a 6-degree in-plane grid (900)")
    p.add_argument("--kind", choices=("auto",) + known_fitters(), default="auto",
                   help="model kind to fit (default auto: the rule of 'kesbrdf fit', docs/models.md)")
    p.add_argument("--scene", choices=("sphere", "swatch", "drape", "dressform"), default="sphere")
    p.add_argument("--params", default=None, help="JSON object overriding the reference's parameters")
    p.add_argument("--base-color", default=None, metavar="R,G,B",
                   help="render both with this body albedo (default: each one's own body)")
    p.add_argument("--with-prior", action="store_true",
                   help="also fit the fibre prior x residual (kind fibre-prior) to the same measurement and "
                        "render it next to the model")
    p.add_argument("-o", "--output", required=True, help="panel PNG (the numbers go to <stem>.json)")
    add_render_options(p, spp=64, resolution="480x360")
    # one small light in a dark room shows the lobe's shape; 480x360 at 64 spp + OIDN keeps
    # the noise floor below FLIP 0.03 (kesbrdf.render.compare.PANEL_SPP)
    import importlib.util

    p.set_defaults(env="none", denoise=importlib.util.find_spec("pyoidn") is not None)


def run(args) -> int:
    from kesbrdf.cli.render import parse_rgb_flag, render_options
    from kesbrdf.render import compare

    opts = render_options(args, base_color=parse_rgb_flag(args.base_color, "--base-color"))
    check_output(args.output, (".png",))
    stderr(f"comparing {args.reference} ({args.protocol} protocol) on the {args.scene}, "
           f"{opts.resolution[0]}x{opts.resolution[1]}, {opts.spp} spp ...")
    first = "default" if args.kind == "auto" else args.kind
    models = (first,) + (("fibre-prior",) if args.with_prior and first != "fibre-prior" else ())
    r = compare.compare_render(args.reference, args.protocol, args.scene, opts, output=args.output, params=args.params,
                               models=models)
    for name, m in r["models"].items():
        stderr(f"{m['kind']}: FLIP {m['flip']:.4f}  relative RMSE {m['rel_rmse']:.4f}")
    stderr(f"(noise floor: FLIP {r['noise_flip']:.4f}, relative RMSE {r['noise_rel_rmse']:.4f})")
    stderr(f"wrote {r['panel']} and {r['json']}")
    return 0
