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
#: The clip: ``kesbrdf demo`` renders the showcase's preview (render.showcase.PREVIEW:
#: four frames a quarter of the clip apart at 640×360, 4 spp + OIDN); the full clip,
#: native 1280×720 at 24 fps, is ``kesbrdf showcase`` (``make showcase``).  The former
#: demo clip (49 frames at 640×360 upscaled to 720p) took 88 s of the demo's CPU.
CLIP_SPP = 4
CLIP_RENDER_SIZE = (640, 360)
#: First drape frame of the clip: the end of the showcase's settling (0.75 s at 24 fps).
CLIP_FIRST_FRAME = 18



def _studio(spp: int, resolution=(1280, 720), **kw):
    return _scenes.studio_options(spp, resolution, base_color=DEMO_COLOUR, **kw)


def run_demo(model_path, out_dir, drape_dir=None, progress=None, garment_dir=None,
             still_spp: int = STILL_SPP, clip_spp: int = CLIP_SPP, clip_first_frame: int = CLIP_FIRST_FRAME) -> dict:
    """Write the demo's renders into ``out_dir``; returns {name: path}.

    ``drape_dir`` is a ``kesbrdf drape`` folder (the sheet on the sphere); without one a
    procedural drape sequence stands in.  ``garment_dir`` is a ``kesbrdf drape --scene
    garment`` folder (the sewn skirt on the turning mannequin): its last frame is the
    garment still and the colourways, and frames from ``clip_first_frame`` on are the
    clip preview (``garment_preview.mp4``/``.gif``/``_strip.png``: four frames at 640×360;
    ``garment_dir`` must hold the drape of :data:`kesbrdf.render.showcase.PREVIEW`).  Without it the
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
        from dataclasses import replace

        from kesbrdf.render import showcase as _showcase

        spec = replace(_showcase.PREVIEW, spp=clip_spp)
        say(f"render: clip preview, {spec.frames} frames spread over the clip ({spec.size[0]}x{spec.size[1]}, "
            f"{spec.spp} spp + OIDN); the full 1280x720 clip: kesbrdf showcase (make showcase)")
        res = _showcase.run_showcase(model_path, out, spec, name="garment_preview", drape_dir=garment.root,
                                     render_progress=frames)
        written["animation"] = res["video"]
        written["gif"] = res["gif"]
        written["strip"] = res["strip"]
    else:
        anim = _scenes.RenderOptions(spp=16, resolution=(240, 180), base_color=DEMO_COLOUR, env="studio", light="area")
        say(f"render: animation of {len(drape.frames)} frames")
        written["animation"] = _animation.render_animation(model_path, drape.root, out / "drape.mp4", anim,
                                                           progress=frames)
    sheet = _scenes.RenderOptions(spp=16, resolution=(200, 240), env="studio-hdr", light="studio",
                                  denoise=_scenes.can_denoise())
    say("render: colourways")
    written["colourways"] = _colourways.render_colourways(
        model_path, out / "colourways.png", sheet, scene=garment_scene, drape=garment
    )
    return written
