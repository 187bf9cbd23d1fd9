"""``kesbrdf render MODEL --scene ... -o IMAGE``: render a model with Mitsuba 3."""

from __future__ import annotations

import math

from kesbrdf.cli._common import check_output, stderr
from kesbrdf.errors import KesbrdfError

HELP = "Render a model (sphere, swatch, draped cloth or dress form) with Mitsuba 3; --animation renders a drape sequence."

SCENES = ("sphere", "swatch", "drape", "dressform", "garment")


def parse_resolution(text: str) -> tuple[int, int]:
    """``"WxH"`` → (W, H)."""
    w, sep, h = text.lower().partition("x")
    try:
        res = (int(w), int(h))
    except ValueError:
        res = None
    if not sep or res is None or min(res) <= 0:
        raise KesbrdfError(f"--resolution: expected WxH such as 320x240, got {text!r}")
    return res


def parse_rgb_flag(text: str | None, flag: str):
    if text is None:
        return None
    parts = text.split(",")
    try:
        rgb = tuple(float(p) for p in parts)
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or min(rgb) < 0:
        raise KesbrdfError(f"{flag}: expected three non-negative numbers R,G,B, got {text!r}")
    return rgb


#: ``--exposure card``: meter the scene once on an 18 % grey card (docs/rendering.md, "Studio").
CARD = "card"


def parse_exposure(text: str):
    """``--exposure``: stops (a finite number) or ``card``."""
    if text.strip().lower() == CARD:
        return CARD
    try:
        stops = float(text)
    except ValueError:
        stops = math.nan
    if not math.isfinite(stops):
        raise KesbrdfError(f"--exposure: expected stops (a number such as -1.5) or 'card', got {text!r}")
    return stops


def add_render_options(p, spp: int = 64, resolution: str = "480x360") -> None:
    """Flags shared by ``render`` and ``colourways``."""
    p.add_argument("--spp", type=int, default=spp, help=f"samples per pixel (default {spp})")
    p.add_argument("--resolution", default=resolution, help=f"image size WxH (default {resolution})")
    p.add_argument("--light", choices=("area", "sun", "none", "studio"), default="area",
                   help="key light (default area); studio: key, fill, rim and top soft boxes (docs/rendering.md)")
    p.add_argument("--env", choices=("studio", "sky", "uniform", "none", "studio-hdr", "sunsky"), default="studio",
                   help="generated environment: studio (soft boxes), sky (gradient + sun), uniform (furnace), none, "
                        "studio-hdr (procedural HDR room), sunsky (Mitsuba's sky model)")
    p.add_argument("--tonemap", choices=("clip", "aces"), default="clip",
                   help="PNG/JPEG tone curve: clip (linear) or aces (filmic, docs/rendering.md)")
    p.add_argument("--denoise", action="store_true",
                   help="denoise with Intel Open Image Denoise using albedo and normal AOVs (pyoidn)")
    p.add_argument("--lobe-tint", default=None, metavar="R,G,B", help="tint of the measured lobe (default 1,1,1)")
    p.add_argument("--mapping", choices=("deviation", "halfvector"), default=None,
                   help="(phi, gamma) mapping of a kes table (docs/formats.md); default: the one the model "
                        "records (halfvector for new fits); 'paper' is not renderable")
    p.add_argument("--one-sided", action="store_true", help="shade back faces black (default: two-sided cloth)")
    p.add_argument("--exposure", default="0", metavar="STOPS|card",
                   help="exposure of PNG/JPEG output: stops (default 0), or 'card': metered once on an 18%% grey "
                        "card in the scene's light, the same for every image of the scene (docs/rendering.md)")
    p.add_argument("--extrapolation", choices=("fade", "hold"), default="fade",
                   help="lobe beyond the last measured deviation: fade to the body (default) or hold (docs/formats.md)")
    p.add_argument("--max-depth", type=int, default=4, help="path length (default 4)")
    p.add_argument("--seed", type=int, default=0, help="sampler seed")


def render_options(args, **extra):
    """The render flags as RenderOptions; ``--exposure card`` gives 0 here (see :func:`metered`)."""
    from kesbrdf.render.scenes import RenderOptions

    stops = parse_exposure(str(args.exposure))
    return RenderOptions(
        spp=args.spp,
        resolution=parse_resolution(args.resolution),
        light=args.light,
        env=args.env,
        lobe_tint=parse_rgb_flag(args.lobe_tint, "--lobe-tint"),
        mapping=args.mapping,
        two_sided=not args.one_sided,
        max_depth=args.max_depth,
        seed=args.seed,
        exposure=0.0 if stops == CARD else stops,
        extrapolation=args.extrapolation,
        tonemap=args.tonemap,
        denoise=args.denoise,
        **extra,
    ).validate()


def metered(args, opts, model, scene: str, **where):
    """``opts`` with the scene's grey-card exposure when ``--exposure card``, else unchanged."""
    if parse_exposure(str(args.exposure)) != CARD:
        return opts
    from dataclasses import replace

    from kesbrdf.render.exposure import meter_exposure

    stops = meter_exposure(model, scene, opts, **where)
    stderr(f"exposure {stops:+.2f} stops, metered on the grey card")
    return replace(opts, exposure=stops)


def add_arguments(p):
    p.add_argument("model", help="model file (.kes.json)")
    p.add_argument("--scene", choices=SCENES, default="sphere", help="scene (default sphere)")
    p.add_argument("-o", "--output", required=True, help="image (.png, .jpg, .exr); with --animation .mp4 or .gif")
    p.add_argument("--animation", metavar="DRAPE_DIR", default=None,
                   help="render every frame of a 'kesbrdf drape' folder to a video (resumable)")
    p.add_argument("--drape", metavar="DRAPE_DIR", default=None,
                   help="for --scene drape/dressform/garment: render this drape folder's frame (default: a procedural garment)")
    p.add_argument("--frame", type=int, default=None, help="frame of --drape to render (default: the last)")
    p.add_argument("--fps", type=float, default=None, help="animation frame rate (default: drape.json's)")
    p.add_argument("--first-frame", type=int, default=0, help="animation: start at this drape frame (default 0)")
    p.add_argument("--gif", default=None, metavar="GIF", help="animation: also write this GIF")
    p.add_argument("--base-color", default=None, metavar="R,G,B",
                   help="body colour: Lambertian albedo of the dyed fabric, each in [0,1] (default: measured body)")
    p.add_argument("--uv-rotation", type=float, default=0.0, metavar="DEG",
                   help="swatch only: turn the UVs (90 puts the warp along the other edge)")
    add_render_options(p)


STILL_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr")
VIDEO_SUFFIXES = (".mp4", ".gif")


def run(args) -> int:
    # the output is checked before Mitsuba is even imported (a render takes seconds to minutes)
    if not args.animation and args.output.lower().endswith(VIDEO_SUFFIXES):
        raise KesbrdfError(f"{args.output}: video output needs --animation DRAPE_DIR")
    check_output(args.output, VIDEO_SUFFIXES if args.animation else STILL_SUFFIXES)
    if args.fps is not None and not 0 < args.fps <= 240:
        raise KesbrdfError(f"--fps: expected frames per second in (0, 240], got {args.fps:g}")
    if args.frame is not None and args.frame < 0:
        raise KesbrdfError(f"--frame: expected a frame number >= 0, got {args.frame}")
    if not math.isfinite(args.uv_rotation):
        raise KesbrdfError(f"--uv-rotation: expected degrees, got {args.uv_rotation}")
    from kesbrdf.render import animation, scenes  # noqa: F401  (registers the BSDF)

    base = parse_rgb_flag(args.base_color, "--base-color")
    if base is not None and max(base) > 1:
        raise KesbrdfError(f"--base-color: expected a body albedo with R,G,B in [0, 1], got {args.base_color!r}")
    opts = render_options(args, base_color=base,
                          uv_rotation_deg=args.uv_rotation)

    if args.animation:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        scene = args.scene if args.scene in ("drape", "dressform", "garment") else None
        # one exposure for the clip: metered on its first frame's scene
        opts = metered(args, opts, args.model, scene or "drape", drape=args.animation, frame=args.first_frame)
        with Progress(TextColumn("rendering frames"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                      transient=True) as bar:
            task = bar.add_task("frames", total=None)
            kept = []

            def progress(done, total, skipped):
                bar.update(task, completed=done, total=total)
                if skipped:
                    kept.append(done)

            out = animation.render_animation(args.model, args.animation, args.output, opts, scene=scene,
                                             fps=args.fps, progress=progress, first_frame=args.first_frame,
                                             gif=args.gif)
        note = f" ({len(kept)} frame(s) kept from an earlier run)" if kept else ""
        stderr(f"wrote {out}{note}")
        return 0
    from kesbrdf.io.model_file import load_model

    load_model(args.model)  # a bad model file is the one line on stderr, before any "rendering ..."
    opts = metered(args, opts, args.model, args.scene, drape=args.drape, frame=args.frame)
    stderr(f"rendering {args.scene} at {opts.resolution[0]}x{opts.resolution[1]}, {opts.spp} spp ...")
    out = scenes.render_still(args.model, args.scene, args.output, opts, drape=args.drape, frame=args.frame)
    stderr(f"wrote {out}")
    return 0
