"""The renders of ``kesbrdf demo``: sphere, draped cloth, garment, the clip, colourways.

Stills are 1280×720 in the studio (:mod:`kesbrdf.render.studio`), tone-mapped with the
ACES curve and denoised with OIDN (:mod:`kesbrdf.render.post`); the clip of the turning
mannequin is 720p at a low spp, denoised, so that the demo stays within its time budget.
"""

from __future__ import annotations

from pathlib import Path

from kesbrdf.render import animation as _animation
from kesbrdf.render import colourways as _colourways
from kesbrdf.render import mesh as _mesh
from kesbrdf.render import scenes as _scenes

__all__ = ["run_demo", "DEMO_COLOUR"]

#: Body colour of the demo stills: None = the measured body.  The embedded fabric is a
#: black satin; a 0.45 red body (the former value) is as bright as its 0.19 1/sr sheen
#: and rendered it pink and matte (docs/rendering.md, "Satin findings").  Dyed
#: versions ("arbitrarily coloured satin", docs/method.md, "Colour") are the colourway sheet's job.
DEMO_COLOUR = None


#: Stills: 1280×720, studio lights + HDR room, ACES, denoised.
STILL_SPP = 8
#: The clip: rendered at CLIP_RENDER_SIZE with CLIP_SPP and OIDN, written at 1280×720
#: (Lanczos); native 720p at full quality is ``kesbrdf render --animation ...
#: --resolution 1280x720 --spp 64 --denoise`` (docs/rendering.md).  Measured in one run
#: on the shared 2-core machine: a 640×360 frame at 4 spp + OIDN, upscaled, costs 1.6 s
#: of CPU; a native 1280×720 frame at the least possible 1 spp costs 2.8–3.0 s (path
#: tracing 1.2–1.4 s, OIDN at four times the pixels 1.5 s; OIDN's "fast" mode halves
#: that but leaves speckles along the silhouettes).  For 49 frames that is 60–70 s more,
#: which takes the demo (160 s) past its 3 minutes, so the demo upscales.
CLIP_SPP = 4
CLIP_RENDER_SIZE = (640, 360)
#: First drape frame of the clip (the skirt has settled; the turn starts at 0.6 s).
CLIP_FIRST_FRAME = 17


def _can_denoise() -> bool:
    import importlib.util

    return importlib.util.find_spec("pyoidn") is not None


def _studio(spp: int, resolution=(1280, 720), **kw):
    return _scenes.RenderOptions(spp=spp, resolution=resolution, base_color=DEMO_COLOUR, env="studio-hdr",
                                 light="studio", tonemap="aces", denoise=_can_denoise(), **kw)


def run_demo(model_path, out_dir, drape_dir=None, progress=None, garment_dir=None,
             still_spp: int = STILL_SPP, clip_spp: int = CLIP_SPP, clip_first_frame: int = CLIP_FIRST_FRAME) -> dict:
    """Write the demo's renders into ``out_dir``; returns {name: path}.

    ``drape_dir`` is a ``kesbrdf drape`` folder (the sheet on the sphere); without one a
    procedural drape sequence stands in.  ``garment_dir`` is a ``kesbrdf drape --scene
    garment`` folder (the sewn skirt on the turning mannequin): its last frame is the
    garment still and the colourways, and frames from ``clip_first_frame`` on are the
    clip (``garment.mp4`` at 1280×720 and ``garment.gif`` at 640×360).  Without it the
    older primitive dress form and a procedural skirt stand in, and the sphere drape is
    animated instead.  ``progress`` is called with one line of text per step.
    """
    say = progress or (lambda text: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    still = _studio(still_spp)
    written = {}
    say("render: sphere (1280x720, studio)")
    written["sphere"] = _scenes.render_still(model_path, "sphere", out / "sphere.png", still)
    if drape_dir is None:
        say("render: no cloth simulation given; using a procedural drape sequence")
        drape_dir = _mesh.procedural_drape(out / "procedural_drape", frames=24)
    drape = _scenes.read_drape(drape_dir)
    drape_scene = "dressform" if drape.scene == "dressform" else "drape"
    say(f"render: draped cloth ({drape.root})")
    written["drape"] = _scenes.render_still(model_path, drape_scene, out / "drape.png", still, drape=drape)
    garment = _scenes.read_drape(garment_dir) if garment_dir is not None else None
    garment_scene = "garment" if garment is not None and garment.scene == "garment" else "dressform"
    say("render: garment on the mannequin" + (" (sewn skirt)" if garment else " (procedural skirt)"))
    # the settled skirt seen from the front, just before the mannequin starts to turn
    still_frame = min(clip_first_frame, len(garment.frames) - 1) if garment_scene == "garment" else None
    written["garment"] = _scenes.render_still(model_path, garment_scene, out / "garment.png", still, drape=garment,
                                              frame=still_frame)

    def frames(done, total, skipped):
        if done == total or done % 10 == 0:
            say(f"  frame {done}/{total}{' (kept)' if skipped else ''}")

    if garment_scene == "garment":
        clip = _studio(clip_spp, resolution=CLIP_RENDER_SIZE, max_depth=3)
        first = min(clip_first_frame, len(garment.frames) - 1)
        say(f"render: clip of {len(garment.frames) - first} frames ({CLIP_RENDER_SIZE[0]}x{CLIP_RENDER_SIZE[1]}, "
            f"{clip_spp} spp + OIDN, upscaled to 1280x720: native 720p is ~1.8x the CPU a frame, "
            "past the demo's 3 min; docs/rendering.md)")
        written["animation"] = _animation.render_animation(
            model_path, garment.root, out / "garment.mp4", clip, progress=frames, first_frame=first,
            gif=out / "garment.gif", gif_width=640, upscale_to=(1280, 720))
        written["gif"] = out / "garment.gif"
    else:
        anim = _scenes.RenderOptions(spp=16, resolution=(240, 180), base_color=DEMO_COLOUR, env="studio", light="area")
        say(f"render: animation of {len(drape.frames)} frames")
        written["animation"] = _animation.render_animation(model_path, drape.root, out / "drape.mp4", anim,
                                                           progress=frames)
    sheet = _scenes.RenderOptions(spp=16, resolution=(200, 240), env="studio-hdr", light="studio",
                                  denoise=_can_denoise())
    say("render: colourways")
    written["colourways"] = _colourways.render_colourways(
        model_path, out / "colourways.png", sheet, scene=garment_scene, drape=garment
    )
    return written
