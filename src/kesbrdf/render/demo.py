"""The renders of ``kesbrdf demo``: reference chart, sphere, draped cloth, garment, the
clip, colourways.

Stills are 1280×720 in the studio (:mod:`kesbrdf.render.studio`), tone-mapped with the
ACES curve and denoised with OIDN (:mod:`kesbrdf.render.post`); the clip of the turning
mannequin is 720p at a low spp, denoised, so that the demo stays within its time budget.
Exposure: metered once per scene on an 18 % grey card (:func:`kesbrdf.render.exposure.meter_exposure`),
never on the image; the garment's exposure serves its still, the clip and the colourway
sheet (docs/rendering.md, "Studio").
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from kesbrdf._atomic import write_text
from kesbrdf.render import animation as _animation
from kesbrdf.render import chart as _chart
from kesbrdf.render import colourways as _colourways
from kesbrdf.render import mesh as _mesh
from kesbrdf.render import scenes as _scenes
from kesbrdf.render import exposure as _exposure

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
#: The colourway sheet: 4 × 2 tiles of 480 × 540 = 1920 × 1080, at COLOURWAY_SPP + OIDN
#: (4 spp denoised: 8.3 M samples for the sheet, against 6.1 M for the former 800 × 480
#: sheet at 16 spp without denoising).
COLOURWAY_TILE = (480, 540)
COLOURWAY_SPP = 4
#: The reference chart (black satin, white fabric, grey card): 1280 × 720.
CHART_SPP = 8



def _studio(spp: int, resolution=(1280, 720), **kw):
    return _scenes.studio_options(spp, resolution, base_color=DEMO_COLOUR, **kw)


def run_demo(model_path, out_dir, drape_dir=None, progress=None, garment_dir=None,
             still_spp: int = STILL_SPP, clip_spp: int = CLIP_SPP, clip_first_frame: int = CLIP_FIRST_FRAME,
             drapes=None) -> dict:
    """Write the demo's renders into ``out_dir``; returns {name: path}.

    ``drape_dir`` is a ``kesbrdf drape`` folder (the sheet on the sphere); without one a
    procedural drape sequence stands in.  ``garment_dir`` is a ``kesbrdf drape --scene
    garment`` folder (the sewn skirt on the turning mannequin): its last frame is the
    garment still and the colourways, and frames from ``clip_first_frame`` on are the
    clip preview (``garment_preview.mp4``/``.gif``/``_strip.png``: four frames at 640×360;
    ``garment_dir`` must hold the drape of :data:`kesbrdf.render.showcase.PREVIEW`).  Without it the
    older primitive dress form and a procedural skirt stand in, and the sphere drape is
    animated instead.  ``progress`` is called with one line of text per step.
    ``drapes``: a callable returning ``(drape_dir, garment_dir)``, called after the chart
    and the sphere (which need no drape), so that drapes simulated elsewhere can finish
    meanwhile; it replaces the two arguments.
    """
    say = progress or (lambda text: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    still = _studio(still_spp)
    written = {}
    exposures = {}

    def metered(scene, drape=None, frame=None):
        e = _exposure.meter_exposure(model_path, scene, still, drape=drape, frame=frame)
        exposures[scene] = round(e, 4)
        return replace(still, exposure=e)

    say("render: reference chart (black satin, white fabric, 18 % grey card; exposure metered on the card)")
    written["chart"], _ = _chart.render_chart(model_path, out / "chart.png", _studio(CHART_SPP))
    say("render: sphere (1280x720, studio)")
    written["sphere"] = _scenes.render_still(model_path, "sphere", out / "sphere.png", metered("sphere"))
    if drapes is not None:
        drape_dir, garment_dir = drapes()
    if drape_dir is None:
        say("render: no cloth simulation given; using a procedural drape sequence")
        drape_dir = _mesh.procedural_drape(out / "procedural_drape", frames=24)
    drape = _scenes.read_drape(drape_dir)
    drape_scene = "dressform" if drape.scene == "dressform" else "drape"
    say(f"render: draped cloth ({drape.root})")
    written["drape"] = _scenes.render_still(model_path, drape_scene, out / "drape.png", metered(drape_scene, drape),
                                            drape=drape)
    garment = _scenes.read_drape(garment_dir) if garment_dir is not None else None
    garment_scene = "garment" if garment is not None and garment.scene == "garment" else "dressform"
    say("render: garment on the mannequin" + (" (sewn skirt)" if garment else " (procedural skirt)"))
    # the settled skirt seen from the front, just before the mannequin starts to turn
    still_frame = min(clip_first_frame, len(garment.frames) - 1) if garment_scene == "garment" else None
    garment_still = metered(garment_scene, garment, still_frame)
    written["garment"] = _scenes.render_still(model_path, garment_scene, out / "garment.png", garment_still,
                                              drape=garment, frame=still_frame)

    def frames(done, total, skipped):
        if done == total or done % 10 == 0:
            say(f"  frame {done}/{total}{' (kept)' if skipped else ''}")

    if garment_scene == "garment":
        from kesbrdf.render import showcase as _showcase

        spec = replace(_showcase.PREVIEW, spp=clip_spp)
        say(f"render: clip preview, {spec.frames} frames spread over the clip ({spec.size[0]}x{spec.size[1]}, "
            f"{spec.spp} spp + OIDN); the full 1280x720 clip: kesbrdf showcase (make showcase)")
        clip = _studio(spec.spp, resolution=tuple(spec.size), max_depth=3, exposure=garment_still.exposure)
        res = _showcase.run_showcase(model_path, out, spec, name="garment_preview", drape_dir=garment.root,
                                     render_progress=frames, opts=clip)
        written["animation"] = res["video"]
        written["gif"] = res["gif"]
        written["strip"] = res["strip"]
    else:
        anim = _scenes.RenderOptions(spp=16, resolution=(240, 180), base_color=DEMO_COLOUR, env="studio", light="area")
        say(f"render: animation of {len(drape.frames)} frames")
        written["animation"] = _animation.render_animation(model_path, drape.root, out / "drape.mp4", anim,
                                                           progress=frames)
    sheet = replace(garment_still, spp=COLOURWAY_SPP, resolution=COLOURWAY_TILE, base_color=None)
    say(f"render: colourways (1920x1080 sheet, {COLOURWAY_SPP} spp + OIDN, the garment's exposure)")
    written["colourways"] = _colourways.render_colourways(
        model_path, out / "colourways.png", sheet, scene=garment_scene, drape=garment
    )
    write_text(out / "exposure.json", json.dumps({"rule": "18 % grey card, metered once per scene",
                                                 "tone_curve": "aces", "stops": exposures}, indent=1) + "\n")
    written["exposure"] = out / "exposure.json"
    return written
