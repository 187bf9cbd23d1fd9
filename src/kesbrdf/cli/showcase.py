"""``kesbrdf showcase``: the 4.5 s clip of the sewn satin skirt on the turning mannequin.

Simulates the garment (newton), renders every frame natively at 1280×720 in the studio,
denoised, and writes ``showcase.mp4``, ``showcase.gif`` and ``showcase_strip.png``
(:mod:`kesbrdf.render.showcase`).  ``--preview`` renders the four frames that
``kesbrdf demo`` shows instead.  Resumable: a re-run keeps the drape and the frames.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from kesbrdf.cli._common import check_output, stderr
from kesbrdf.errors import KesbrdfError

HELP = "Render the showcase clip: the satin skirt on the turning mannequin, 4.5 s at 24 fps, 1280x720 (MP4 + GIF)."


def add_arguments(p):
    p.add_argument("model", nargs="?", default=None,
                   help="model file (default: fit the embedded virtual black satin, as `kesbrdf demo` does)")
    p.add_argument("-o", "--output", default="out/showcase", help="output folder (default out/showcase)")
    p.add_argument("--preview", action="store_true", help="only the demo's preview: 4 frames at 640x360")
    p.add_argument("--spp", type=int, default=None, help="samples a pixel before denoising (default 8; preview 4)")
    p.add_argument("--resolution", default=None, metavar="WxH", help="frame size (default 1280x720)")
    p.add_argument("--frames", type=int, default=None,
                   help="render only this many frames, evenly spaced over the clip (a quick look)")


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise KesbrdfError(f"--resolution: expected WIDTHxHEIGHT such as 1280x720, got {text!r}") from None
    if not (16 <= w <= 7680 and 16 <= h <= 4320):
        raise KesbrdfError(f"--resolution: expected 16..7680 x 16..4320 pixels, got {text!r}")
    return w, h


def _default_model(out: Path) -> Path:
    """Fit the embedded sample (as the demo does) into ``out/model.kes.json``, once."""
    path = out / "model.kes.json"
    if path.is_file():
        return path
    import kesbrdf
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.measure import demo_data

    manifest = demo_data.embedded_manifest()
    if manifest is not None:
        from kesbrdf.measure.acquisition.ingest import ingest

        m = ingest(manifest).measurement
    else:
        m = read_measurement(demo_data.embedded_measurement())
    model = kesbrdf.fit(m, kind="kes")[0]
    model.save(path)
    return path


class _ProgressLog:
    """Plain progress lines for a log: ``render: 20/108, 4:02 elapsed, ETA 17:40``.

    One line every :attr:`LOG_EVERY` steps and at the end; the ETA extrapolates the
    stage's mean time a step so far.
    """

    LOG_EVERY = 10

    def __init__(self):
        self.start: dict[str, tuple[float, int]] = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.perf_counter()
        t0, d0 = self.start.setdefault(stage, (now, done))
        if not (done == total or (done > d0 and done % self.LOG_EVERY == 0)):
            return
        elapsed = now - t0
        rate = elapsed / (done - d0) if done > d0 else None
        eta = "" if rate is None or done >= total else f", ETA {_clock(rate * (total - done))}"
        stderr(f"{stage}: {done}/{total}, {_clock(elapsed)} elapsed{eta}")


def _clock(seconds: float) -> str:
    m, s = divmod(int(round(seconds)), 60)
    return f"{m}:{s:02d}"


def run(args) -> int:
    from kesbrdf.render import showcase

    out = check_output(args.output, folder=True)
    spec = showcase.PREVIEW if args.preview else showcase.SHOWCASE
    if args.spp is not None:
        if not 1 <= args.spp <= 4096:
            raise KesbrdfError(f"--spp: expected samples a pixel in [1, 4096], got {args.spp}")
        spec = replace(spec, spp=args.spp)
    if args.resolution is not None:
        spec = replace(spec, size=_size(args.resolution))
    if args.frames is not None:
        if not 1 <= args.frames <= spec.clip_frame_count:
            raise KesbrdfError(f"--frames: expected 1..{spec.clip_frame_count}, got {args.frames}")
        spec = replace(spec, frames=args.frames)
    if args.model is not None and not Path(args.model).is_file():
        raise FileNotFoundError(2, "No such file or directory", str(args.model))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    model = Path(args.model) if args.model else _default_model(out)

    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
               TextColumn("ETA"), TimeRemainingColumn())
    times: dict = {}
    console = Console(stderr=True)
    # rich draws its bar on a terminal only: into a log (CI, nohup, a pipe) the progress
    # goes as a plain line every LOG_EVERY-th step, with the elapsed time and an ETA
    log = None if console.is_terminal else _ProgressLog()
    with Progress(*columns, console=console) as bar:
        sim = bar.add_task(f"simulate (cloth {spec.cloth_resolution}, {spec.sim_frames} frames)", total=spec.sim_frames)
        ren = bar.add_task(f"render {spec.size[0]}x{spec.size[1]} {spec.spp} spp + OIDN", total=None, start=False)

        def sim_progress(done, total):
            bar.update(sim, completed=done, total=total)
            if log is not None:
                log("simulate", done, total)

        def render_progress(done, total, skipped):
            if "render_start" not in times:
                times["render_start"] = time.perf_counter()
                bar.start_task(ren)
            bar.update(ren, completed=done, total=total)
            if log is not None:
                log("render", done, total)

        t_sim = time.perf_counter()

        def sim_then_mark(done, total):
            sim_progress(done, total)
            if done >= total:
                times.setdefault("sim_end", time.perf_counter())

        result = showcase.run_showcase(model, out, spec, sim_progress=sim_then_mark, render_progress=render_progress)
    t_end = time.perf_counter()
    n = len(showcase.clip_frames(spec))
    r0 = times.get("render_start", t_sim)
    stderr(f"simulation {times.get('sim_end', r0) - t_sim:.1f} s; rendering {n} frames {t_end - r0:.1f} s "
           f"({(t_end - r0) / max(n, 1):.2f} s a frame, encoding included); total {t_end - t0:.1f} s")
    stderr(f"wrote {result['video']}, {result['gif']} and {result['strip']}")
    return 0
