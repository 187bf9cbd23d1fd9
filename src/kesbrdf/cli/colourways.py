"""``kesbrdf colourways MODEL -o SHEET.png``: one garment in several body colours."""

from __future__ import annotations

from kesbrdf.cli._common import check_output, stderr
from kesbrdf.cli.render import add_render_options, metered, render_options

HELP = "Render a contact sheet of one garment in >= 6 colourways (same gloss and anisotropy, new body colour)."


def add_arguments(p):
    p.add_argument("model", help="model file (.kes.json)")
    p.add_argument("-o", "--output", required=True, help="contact sheet (.png)")
    p.add_argument("--scene", choices=("sphere", "swatch", "drape", "dressform"), default="dressform",
                   help="garment scene (default dressform)")
    p.add_argument("--drape", metavar="DRAPE_DIR", default=None, help="render this drape folder's last frame")
    p.add_argument("--colours", default=None, metavar="NAME=R,G,B;...",
                   help="body albedos in [0,1] (NAME=measured keeps the measured body), at least 6 "
                        "(default: ivory, crimson, emerald, navy, gold, plum, teal, black = measured)")
    p.add_argument("--columns", type=int, default=4, help="tiles per row (default 4)")
    add_render_options(p, spp=32, resolution="200x240")


def run(args) -> int:
    check_output(args.output, (".png",))
    if args.columns < 1:
        from kesbrdf.errors import KesbrdfError

        raise KesbrdfError(f"--columns: expected tiles per row >= 1, got {args.columns}")
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from kesbrdf.render import colourways

    opts = metered(args, render_options(args), args.model, args.scene, drape=args.drape)
    cw = colourways.parse_colourways(args.colours) if args.colours else None
    with Progress(TextColumn("rendering colourways"), BarColumn(), MofNCompleteColumn(), transient=True) as bar:
        task = bar.add_task("tiles", total=None)
        out = colourways.render_colourways(
            args.model, args.output, opts, scene=args.scene, drape=args.drape, colourways=cw, columns=args.columns,
            progress=lambda done, total, name: bar.update(task, completed=done, total=total),
        )
    stderr(f"wrote {out}")
    return 0
