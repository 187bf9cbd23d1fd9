"""The showcase clip: the sewn skirt on the mannequin turning half a turn, native 720p.

The paper closes on its application, a dressing simulation of coloured satin shown as a
clip.  :func:`run_showcase` makes that clip from a model file (docs/rendering.md, "The
showcase clip"):

1. **Simulate** (:func:`kesbrdf.cloth.drape.simulate_drape`, scene ``garment``): the
   six-gore skirt with its bias-cut centre front at cloth resolution
   :attr:`ShowcaseSpec.cloth_resolution`, settling for ``settle_s``, then the mannequin
   turns ``turn_deg`` (smooth start and stop) and stands still while the skirt swings on.
   The cloth is simulated through the whole turn, so it follows with inertia: the hem
   lags while the body accelerates and swings past when it stops.
2. **Render** (:func:`kesbrdf.render.animation.render_animation`): every frame from the
   end of the settling, natively at ``size`` (no upscaling), ``spp`` samples a pixel,
   denoised with Open Image Denoise (pyoidn), in the studio; the cloth is the welded,
   Loop-subdivided render mesh (:mod:`kesbrdf.cloth.render_mesh`).
3. **Encode**: ``showcase.mp4`` (H.264 via imageio-ffmpeg) and ``showcase.gif``
   (``gif_width`` wide), and ``showcase_strip.png``, four frames side by side.

:data:`SHOWCASE` is the full clip (``make showcase``); :data:`PREVIEW` is the few
frames that ``kesbrdf demo`` renders within its time budget.  Both are resumable: the
drape and the rendered frames are kept in ``out_dir`` and reused by a re-run with the
same settings.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from kesbrdf._atomic import write_text

__all__ = ["ShowcaseSpec", "SHOWCASE", "PREVIEW", "run_showcase", "clip_frames", "write_strip"]


@dataclass(frozen=True)
class ShowcaseSpec:
    """What the clip shows and how it is rendered.

    fps : frames per second of the simulation and of the clip.
    settle_s : simulated time before the clip starts (the skirt settles on the body).
    clip_s : length of the clip [s].
    turn_deg, turn_start_s, turn_duration_s : the mannequin's turn (seconds from the
        start of the simulation; (1 − cos πx)/2 easing, docs/drape.md).
    cloth_resolution : ``kesbrdf drape --resolution`` of the garment (rows down a gore
        are half of it, cells across a quarter).
    size : (width, height) of the rendered frames, pixels.
    spp : samples a pixel (then denoised).
    frames : None renders every frame of the clip; an int renders that many, evenly
        spaced over it (a preview).
    gif_width : width of the GIF [px].
    """

    fps: float = 24.0
    settle_s: float = 0.75
    clip_s: float = 4.5
    turn_deg: float = 180.0
    turn_start_s: float = 1.0
    turn_duration_s: float = 2.5
    cloth_resolution: int = 72
    size: tuple[int, int] = (1280, 720)
    spp: int = 8
    frames: int | None = None
    gif_width: int = 640

    @property
    def first_frame(self) -> int:
        return int(round(self.settle_s * self.fps))

    @property
    def clip_frame_count(self) -> int:
        return int(round(self.clip_s * self.fps))

    @property
    def sim_frames(self) -> int:
        return self.first_frame + self.clip_frame_count

    def drape_kwargs(self) -> dict:
        return dict(fps=self.fps, resolution=self.cloth_resolution, turn_deg=self.turn_deg,
                    turn_start_s=self.turn_start_s, turn_duration_s=self.turn_duration_s)


#: The full clip (``make showcase``): 4.5 s at 24 fps, native 1280×720, 8 spp + OIDN.
#: The turn (180° in 2.5 s from t = 1 s) ends 1.25 s before the clip does, so the
#: skirt is seen swinging on after the body stops.
SHOWCASE = ShowcaseSpec()
#: ``kesbrdf demo``'s preview: the same motion on a coarser cloth (resolution 40, a
#: tenth of the simulation cost), four frames a quarter of the clip apart at 640×360.
PREVIEW = replace(SHOWCASE, cloth_resolution=40, size=(640, 360), spp=4, frames=4, gif_width=640)


def clip_frames(spec: ShowcaseSpec) -> list[int]:
    """Drape frame indices the clip renders (every frame, or ``spec.frames`` evenly spaced)."""
    first, n = spec.first_frame, spec.clip_frame_count
    if spec.frames is None or spec.frames >= n:
        return list(range(first, first + n))
    k = max(int(spec.frames), 1)
    return [first + int(round(i * (n - 1) / max(k - 1, 1))) for i in range(k)]


def write_strip(frame_paths, output, height: int = 360) -> Path:
    """``frame_paths`` side by side (each scaled to ``height``) in one PNG, atomically."""
    from PIL import Image

    from kesbrdf._atomic import atomic_path

    ims = [Image.open(p).convert("RGB") for p in frame_paths]
    ims = [im.resize((int(round(im.width * height / im.height)), height), Image.Resampling.LANCZOS) for im in ims]
    strip = Image.new("RGB", (sum(im.width for im in ims), height))
    x = 0
    for im in ims:
        strip.paste(im, (x, 0))
        x += im.width
    with atomic_path(output) as tmp:
        strip.save(tmp, format="PNG")
    return Path(output)


def run_showcase(model_path, out_dir, spec: ShowcaseSpec = SHOWCASE, name: str = "showcase",
                 sim_progress=None, render_progress=None, opts=None, drape_dir=None) -> dict:
    """Simulate, render and encode the clip into ``out_dir``; returns ``{name: path}``.

    ``sim_progress(done, total)`` and ``render_progress(done, total, skipped)`` are called
    per frame.  ``opts`` (a :class:`~kesbrdf.render.scenes.RenderOptions`) overrides the
    studio options built from ``spec``; ``drape_dir`` reuses a garment drape folder made
    with ``spec.drape_kwargs()`` (default ``out_dir/<name>_drape``).
    """
    from kesbrdf.cloth.drape import simulate_drape
    from kesbrdf.render import animation as _animation
    from kesbrdf.render import scenes as _scenes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    drape_dir = Path(drape_dir) if drape_dir is not None else out / f"{name}_drape"
    simulate_drape("garment", drape_dir, spec.sim_frames, overwrite=True, progress=sim_progress,
                   **spec.drape_kwargs())
    frames = clip_frames(spec)
    if opts is None:  # the studio at the exposure metered on the grey card (docs/rendering.md, "Studio")
        from dataclasses import replace

        from kesbrdf.render.exposure import meter_exposure

        opts = _scenes.studio_options(spec.spp, resolution=tuple(spec.size), max_depth=3)
        opts = replace(opts, exposure=meter_exposure(model_path, "garment", opts, drape=drape_dir, frame=frames[0]))
    video = out / f"{name}.mp4"
    gif = out / f"{name}.gif"
    # a preview of a few frames plays them at about one per second of the motion
    fps = spec.fps if spec.frames is None else max(len(frames) / spec.clip_s, 1.0)
    _animation.render_animation(model_path, drape_dir, video, opts, scene="garment", fps=fps,
                                progress=render_progress, frame_indices=frames, gif=gif,
                                gif_width=spec.gif_width)
    rendered = sorted((out / f"{name}_frames").glob("frame_[0-9][0-9][0-9][0-9].png"))
    pick = [rendered[int(round(i * (len(rendered) - 1) / 3))] for i in range(4)] if len(rendered) >= 4 else rendered
    strip = write_strip(pick, out / f"{name}_strip.png", height=min(360, int(spec.size[1])))
    meta = {"spec": asdict(spec), "drape": str(drape_dir), "frames": frames, "video": video.name, "gif": gif.name,
            "strip": strip.name, "duration_s": len(frames) / spec.fps if spec.frames is None else None,
            "body_turn_deg": spec.turn_deg,
            "turn_per_frame_deg": spec.turn_deg / (spec.turn_duration_s * spec.fps) if spec.turn_duration_s else math.inf}
    write_text(out / f"{name}.json", json.dumps(meta, indent=1) + "\n")
    return {"video": video, "gif": gif, "strip": strip, "drape": drape_dir, "frames_dir": out / f"{name}_frames"}
