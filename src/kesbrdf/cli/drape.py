"""``kesbrdf drape``: simulate satin draped over a sphere or a dress form (newton XPBD).

Writes ``frame_NNNN.ply`` (x y z nx ny nz u v; u along the warp), ``collider_K.ply`` and
``drape.json`` into the output folder; a re-run with the same parameters resumes after
the last finished frame.  See docs/drape.md.
"""

from __future__ import annotations

import time

from kesbrdf.cli._common import check_output

HELP = "Simulate a satin drape (sheet onto a sphere, skirt on a dress form) and write a PLY sequence."


def add_arguments(p):
    p.add_argument("--scene", choices=("sphere", "dressform", "garment"), default="sphere",
                   help="sphere: a 1 m sheet falls onto a sphere; dressform: an A-line skirt on a dress form; "
                        "garment: a six-gore skirt sewn from pattern panels on the procedural mannequin")
    p.add_argument("-o", "--output", required=True, help="output folder (frames, colliders, drape.json)")
    p.add_argument("--frames", type=int, default=120, help="frames to write, frame 0 is t = 0 (default 120)")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second (default 30)")
    p.add_argument("--resolution", type=int, default=48, help="cloth cells along the warp (default 48)")
    p.add_argument("--seed", type=int, default=0, help="seed of the initial perturbation (default 0)")
    p.add_argument("--density-gsm", type=float, default=120.0, help="fabric areal density in g/m² (default 120)")
    p.add_argument("--bending", type=float, default=None, metavar="N_M",
                   help="bending rigidity in N·m (default 5e-6)")
    p.add_argument("--turn-deg", type=float, default=0.0,
                   help="garment: the mannequin turns by this angle (default 0: stands still)")
    p.add_argument("--turn-start", type=float, default=0.8, help="garment: when the turn starts, s (default 0.8)")
    p.add_argument("--turn-duration", type=float, default=1.2, help="garment: how long the turn takes, s (default 1.2)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a drape with different parameters in the output folder")


def run(args) -> int:
    from kesbrdf.cloth.drape import simulate_drape

    try:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
    except ImportError:  # pragma: no cover - rich is in the cli extra
        Progress = None

    check_output(args.output, folder=True)
    t0 = time.perf_counter()
    kwargs = dict(fps=args.fps, resolution=args.resolution, seed=args.seed, overwrite=args.overwrite,
                  density_kg_m2=args.density_gsm / 1000.0)
    if args.scene == "garment":
        kwargs.update(turn_deg=args.turn_deg, turn_start_s=args.turn_start, turn_duration_s=args.turn_duration)
    elif args.turn_deg:
        from kesbrdf.errors import KesbrdfError

        raise KesbrdfError(f"--turn-deg: expected --scene garment (a body that turns), got --scene {args.scene}")
    if args.bending is not None:
        kwargs["bending_rigidity_nm"] = args.bending
    state: dict = {}

    def progress(done: int, total: int) -> None:
        # the bar starts at the first report, i.e. after the parameters were accepted
        if Progress is None:  # pragma: no cover
            return
        if "bar" not in state:
            from rich.console import Console

            columns = (TextColumn("[bold]drape[/] {task.description}"), BarColumn(), MofNCompleteColumn(),
                       TimeElapsedColumn(), TimeRemainingColumn())
            state["bar"] = bar = Progress(*columns, console=Console(stderr=True))
            bar.start()
            state["task"] = bar.add_task(args.scene, total=total)
        state["bar"].update(state["task"], completed=done, total=total)

    try:
        out = simulate_drape(args.scene, args.output, args.frames, progress=progress, **kwargs)
    finally:
        if "bar" in state:
            state["bar"].stop()
    print(f"wrote {args.frames} frames to {out} ({time.perf_counter() - t0:.1f} s); manifest {out / 'drape.json'}")
    return 0
