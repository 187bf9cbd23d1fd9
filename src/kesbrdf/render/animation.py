"""Render a drape sequence (``kesbrdf drape`` folder) to MP4 or GIF, resumably.

Each finished frame is written atomically as ``frame_NNNN.png`` into a frames folder
(default: ``<output stem>_frames`` beside the output) together with ``render.json``,
the parameters it was rendered with.  A re-run with the same parameters skips every
frame already on disk, so an interrupted run resumes; with other parameters the
frames are rendered again.  The video is encoded at the end (MP4 through
imageio-ffmpeg, GIF through Pillow), also atomically, and a sidecar
``<output>.json`` records the provenance.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text
from kesbrdf.errors import KesbrdfError, where
from kesbrdf.render import scenes as _scenes

__all__ = ["render_animation", "encode_video", "VIDEO_FORMATS"]

VIDEO_FORMATS = (".mp4", ".gif")


def _frame_name(i: int) -> str:
    return f"frame_{i:04d}.png"


def encode_video(frame_paths, output, fps: float) -> Path:
    """Encode PNG frames to ``output`` (.mp4 or .gif), atomically."""
    from PIL import Image

    output = Path(output)
    ext = output.suffix.lower()
    if ext not in VIDEO_FORMATS:
        raise KesbrdfError(f"{where(output)}expected an animation file ending .mp4 or .gif, got {ext or 'no suffix'!r}")
    tmp = output.with_name(f".{output.stem}.partial{ext}")
    try:
        if ext == ".gif":
            images = [Image.open(p).convert("RGB") for p in frame_paths]
            images = [im.quantize(colors=256, method=Image.Quantize.MEDIANCUT) for im in images]
            images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                           duration=int(round(1000 / fps)), loop=0)
        else:
            try:
                import imageio.v2 as imageio
                import imageio_ffmpeg  # noqa: F401
            except ImportError as exc:
                raise ImportError(f"MP4 output needs imageio-ffmpeg ({exc}); install kesbrdf[render] or write .gif") from exc
            writer = imageio.get_writer(str(tmp), format="FFMPEG", fps=fps, codec="libx264",
                                        quality=8, macro_block_size=2, pixelformat="yuv420p")
            try:
                for p in frame_paths:
                    writer.append_data(np.asarray(Image.open(p).convert("RGB")))
            finally:
                writer.close()
        os.replace(tmp, output)
    finally:
        if tmp.exists():
            tmp.unlink()
    return output


def render_animation(model_path, drape_dir, output, opts: "_scenes.RenderOptions", scene: str | None = None,
                     fps: float | None = None, frames_dir=None, progress=None) -> Path:
    """Render every frame of a drape folder and encode them to ``output``.

    Parameters
    ----------
    model_path : path
        Model file.
    drape_dir : path
        Folder with ``drape.json`` and the frame PLYs.
    output : path
        ``.mp4`` or ``.gif``.
    opts : RenderOptions
    scene : {"drape", "dressform"}, optional
        Default: ``dressform`` when drape.json says so, else ``drape``.
    fps : float, optional
        Default: drape.json's fps.
    frames_dir : path, optional
        Where the PNG frames go (default ``<output stem>_frames``).
    progress : callable(done, total, skipped), optional
        Called after each frame.

    Returns
    -------
    Path of the video.
    """
    output = Path(output)
    if output.suffix.lower() not in VIDEO_FORMATS:
        raise KesbrdfError(f"{where(output)}expected an animation file ending .mp4 or .gif, got {output.suffix or 'no suffix'!r}")
    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(2, "No such file or directory", str(model_path))
    drape = _scenes.read_drape(drape_dir)
    scene = scene or ("dressform" if drape.scene == "dressform" else "drape")
    if scene not in ("drape", "dressform"):
        raise KesbrdfError(f"animation: expected scene 'drape' or 'dressform', got {scene!r}")
    fps = float(fps or drape.fps)
    frames_dir = Path(frames_dir) if frames_dir else output.with_name(output.stem + "_frames")
    frames_dir.mkdir(parents=True, exist_ok=True)

    meta = _scenes.provenance(model_path, scene, opts, drape)
    meta["drape_frames"] = [p.name for p in drape.frames]
    meta["drape_json_sha256"] = _sha256(drape.root / "drape.json")
    meta_path = frames_dir / "render.json"
    previous = None
    if meta_path.is_file():
        try:
            previous = json.loads(meta_path.read_text(encoding="utf-8"))
        except json.JSONDecodeError:
            previous = None
    if previous != json.loads(json.dumps(meta, default=str)):
        for stale in frames_dir.glob("frame_[0-9][0-9][0-9][0-9].png"):  # other parameters
            stale.unlink()
        write_text(meta_path, json.dumps(meta, indent=1, default=str) + "\n")

    framing = _scenes.scene_framing(drape)
    paths = []
    total = len(drape.frames)
    for i in range(total):
        path = frames_dir / _frame_name(i)
        skipped = path.is_file()
        if not skipped:
            sc = _scenes.load_scene(model_path, scene, opts, drape=drape, frame=i, framing=framing)
            img = _scenes.render_scene(sc, opts)
            _scenes.save_image(path, img, {**meta, "frame": i}, opts.exposure, opts.tonemap)
        paths.append(path)
        if progress is not None:
            progress(i + 1, total, skipped)
    encode_video(paths, output, fps)
    write_text(output.with_name(output.name + ".json"), json.dumps({**meta, "fps": fps}, indent=1, default=str) + "\n")
    return output


def _sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
