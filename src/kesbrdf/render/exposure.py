"""The exposure rule of the studio: metered once per scene on an 18 % grey card.

A photographer sets the exposure on a reference in the scene's light and keeps it for
the set; it is never set per image from the subject.  :func:`meter_exposure` loads the
scene without its subject and with the grey card (:mod:`kesbrdf.render.scenes`,
``GREY_CARD_*``), renders a narrow view the card fills, and returns the exposure (stops)
at which the card is shown at 18 % after the tone curve
(:func:`kesbrdf.render.post.exposure_for`).  docs/rendering.md, "Studio".
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np

from kesbrdf.render import scenes as _scenes
from kesbrdf.render.post import exposure_for

__all__ = ["meter_exposure", "card_reading", "METER_SIZE", "METER_SPP", "luminance"]

#: The meter's render: METER_SIZE² pixels of the card at METER_SPP (262 k samples).  Its
#: mean is repeatable to 0.5 % between seeds (measured on the sphere scene: the card's
#: light is noisy, the windows and soft boxes being small and bright, ±6 % between seeds
#: over a 5 × 4-pixel patch at 64 spp).
METER_SIZE = 32
METER_SPP = 256
_REC709 = np.array([0.2126, 0.7152, 0.0722])
_METERED: dict = {}


def luminance(img) -> np.ndarray:
    """Rec. 709 luminance Y of linear RGB (…, 3)."""
    return np.asarray(img, float)[..., :3] @ _REC709


def card_reading(img, resolution=None) -> float:
    """Mean linear luminance (Rec. 709 Y) of the grey card's pixels in a linear render."""
    img = np.asarray(img, float)
    rows, cols = _scenes.grey_card_box(resolution or (img.shape[1], img.shape[0]))
    return float(luminance(img[rows, cols]).mean())


def meter_reading(scene: "mi.Scene", opts) -> float:  # noqa: F821
    """Exposure (stops) from a meter scene (loaded with ``meter=(METER_SIZE, METER_SPP)``)."""
    return exposure_for(float(luminance(_scenes.render_scene(scene, opts)).mean()), curve=opts.tonemap)


def meter_options(opts):
    """``opts`` as the meter renders them: the card on, no denoising, the meter's spp."""
    return replace(opts, grey_card=True, denoise=False, spp=METER_SPP, seed=0, base_color=None, lobe_tint=None)


def meter_exposure(model_path, scene: str, opts, drape=None, frame=None) -> float:
    """The scene's exposure (stops), metered once on an 18 % grey card.

    The scene is loaded without its subject (cloth, mannequin, dress form;
    :func:`kesbrdf.render.scenes.load_scene` with ``subject=False``) and with the grey
    card at its place in the frame, seen from the camera by a narrow meter view that
    the card fills (:data:`METER_SIZE`, :data:`METER_SPP`); the exposure is the one at
    which the card's mean luminance is shown at 18 % after the tone curve.  Every image
    of that scene (stills, colourways, the clip) then uses it: a black fabric stays
    black, a white one bright.  Without a drape the metered scene does not depend on the
    model, so the reading is cached per scene and options (a batch meters once).
    """
    o = meter_options(opts)
    key = None if drape is not None else json.dumps([scene, o.to_json()], sort_keys=True, default=str)
    if key is not None and key in _METERED:
        return _METERED[key]
    sc = _scenes.load_scene(model_path, scene, o, drape=drape, frame=frame, subject=False,
                            meter=(METER_SIZE, METER_SPP))
    e = meter_reading(sc, o)
    if key is not None:
        _METERED[key] = e
    return e
