"""The renders of ``kesbrdf demo``: sphere, draped cloth, garment, animation, colourways.

Sizes are small on purpose (the demo runs on a shared CPU in CI): a few seconds per
still, about half a second per animation frame after the first-run JIT compile.
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
#: versions ("arbitrarily coloured satin", DESIGN §5) are the colourway sheet's job.
DEMO_COLOUR = None


def run_demo(model_path, out_dir, drape_dir=None, progress=None, garment_dir=None) -> dict:
    """Write sphere.png, drape.png, garment.png, drape.mp4 and colourways.png into ``out_dir``.

    ``drape_dir`` is a ``kesbrdf drape`` folder; without one a procedural drape
    sequence stands in (written to ``out_dir/procedural_drape``).  ``garment_dir`` is
    a ``kesbrdf drape --scene dressform`` folder whose last frame dresses the form in
    the garment still and the colourways; without one a procedural skirt stands in.
    ``progress`` is
    called with one line of text per step.  Returns {name: path}.
    """
    say = progress or (lambda text: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    still = _scenes.RenderOptions(spp=64, resolution=(360, 270), base_color=DEMO_COLOUR, env="studio", light="area")
    written = {}
    say("render: sphere")
    written["sphere"] = _scenes.render_still(model_path, "sphere", out / "sphere.png", still)
    if drape_dir is None:
        say("render: no cloth simulation given; using a procedural drape sequence")
        drape_dir = _mesh.procedural_drape(out / "procedural_drape", frames=24)
    drape = _scenes.read_drape(drape_dir)
    garment_scene = "dressform" if drape.scene == "dressform" else "drape"
    say(f"render: draped cloth ({drape.root})")
    written["drape"] = _scenes.render_still(model_path, garment_scene, out / "drape.png", still, drape=drape)
    garment = _scenes.read_drape(garment_dir) if garment_dir is not None else None
    say("render: garment on the dress form" + (" (simulated skirt)" if garment else " (procedural skirt)"))
    written["garment"] = _scenes.render_still(model_path, "dressform", out / "garment.png", still, drape=garment)
    anim = _scenes.RenderOptions(spp=16, resolution=(240, 180), base_color=DEMO_COLOUR, env="studio", light="area")
    say(f"render: animation of {len(drape.frames)} frames")
    written["animation"] = _animation.render_animation(
        model_path, drape.root, out / "drape.mp4", anim,
        progress=lambda done, total, skipped: say(f"  frame {done}/{total}{' (kept)' if skipped else ''}")
        if done == total or done % 10 == 0 else None,
    )
    sheet = _scenes.RenderOptions(spp=32, resolution=(200, 240), env="studio", light="area")
    say("render: colourways")
    written["colourways"] = _colourways.render_colourways(
        model_path, out / "colourways.png", sheet, scene="dressform", drape=garment
    )
    return written
