"""A photo studio for fabric renders: area lights (soft boxes) and a procedural HDR room.

Everything is generated here (nothing is downloaded).  World space is the renderer's:
y up, the camera in front of the subject on +z.

Lights (:func:`studio_lights`), placed around the subject's centre ``c`` at distances
in units of its bounding radius ``r``, the way satin is lit for a fashion shoot:

=========  ============================  ===========  ==========================
light      direction from c (x, y, z)    size (r)     radiance (relative)
=========  ============================  ===========  ==========================
key        (−0.55, 0.55, 0.80), 3.2 r   0.9 × 1.5    1.6  (soft box, camera left)
fill       (0.85, 0.15, 0.55), 3.5 r    1.4 × 1.4    0.12 (large, dim, right)
rim        (0.35, 1.0, −0.60), 3.0 r    0.3 × 2.2    2.4  (strip light behind)
kicker     (−0.9, 0.2, −0.45), 3.0 r    0.25 × 1.8   2.0  (strip, behind left, low)
=========  ============================  ===========  ==========================

The rectangles face the subject; their solid angles do not depend on r.  A satin's
narrow lobe reflects the key as an elongated highlight that slides along the folds;
the rim and kicker strips draw thin sheen lines on the far edges of folds.

Environment (:func:`environment_map`, kind ``"studio-hdr"``): a latitude–longitude HDR
of a near-black room (floor 0.008, walls 0.012) with two dim overhead soft boxes, a dim
strip behind the camera and three bright windows at eye height (:data:`WINDOWS`), which
a glossy lobe mirrors as thin streaks.  Mitsuba's ``sunsky`` emitter (Mitsuba ≥ 3.6)
can be used instead (``env="sunsky"``).

Exposure (:func:`kesbrdf.render.exposure.meter_exposure`): metered once per scene on an 18 % grey card in the
scene's light, the subject left out, and shown at 18 % after the ACES curve; every
image of the scene shares it (docs/rendering.md, "Studio").
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["STUDIO_LIGHTS", "KEY_RADIANCE", "studio_lights", "environment_map", "look_at_rectangle", "WINDOWS"]

#: (name, direction from the subject, distance / r, (width, height) / r, relative radiance)
STUDIO_LIGHTS = (
    ("key", (-0.55, 0.55, 0.80), 3.2, (0.9, 1.5), 1.6),
    ("fill", (0.85, 0.15, 0.55), 3.5, (1.4, 1.4), 0.12),
    ("rim", (0.35, 1.0, -0.60), 3.0, (0.3, 2.2), 2.4),
    ("kicker", (-0.9, 0.2, -0.45), 3.0, (0.25, 1.8), 2.0),
)
#: Radiance of the key soft box (W sr⁻¹ m⁻² per unit RGB); slightly warm white.
KEY_RADIANCE = (6.0, 5.8, 5.5)


#: Bright windows in the room (direction from the subject, half width, half height in
#: gnomonic units, radiance): two tall windows either side and a wide one behind, at eye
#: height.  A satin's narrow lobe mirrors them as thin bright streaks along the folds,
#: which the broad soft boxes alone do not draw.
WINDOWS = (
    ((-1.0, 0.25, -0.15), 0.12, 0.45, 14.0),
    ((1.0, 0.3, 0.25), 0.1, 0.4, 12.0),
    ((0.0, 0.2, -1.0), 0.5, 0.12, 9.0),
)


def look_at_rectangle(mi, origin, target, size, up=(0.0, 1.0, 0.0)):
    """``to_world`` of a Mitsuba rectangle at ``origin`` facing ``target``, ``size`` = (w, h)."""
    T = mi.ScalarTransform4f
    o = np.asarray(origin, float)
    t = np.asarray(target, float)
    u = np.asarray(up, float)
    if abs(np.dot((t - o) / np.linalg.norm(t - o), u)) > 0.99:  # looking straight down: another up
        u = np.array([0.0, 0.0, -1.0])
    return T().look_at(origin=o.tolist(), target=t.tolist(), up=u.tolist()) @ T().scale([0.5 * size[0], 0.5 * size[1], 1.0])


def studio_lights(mi, center, radius, scale: float = 1.0) -> dict:
    """Scene-dict entries of the four soft boxes around ``center`` (y up)."""
    c = np.asarray(center, float)
    out = {}
    for name, direction, dist, (w, h), rel in STUDIO_LIGHTS:
        d = np.asarray(direction, float)
        d /= np.linalg.norm(d)
        origin = c + dist * radius * d
        rgb = [float(scale * rel * v) for v in KEY_RADIANCE]
        out[f"studio_{name}"] = {
            "type": "rectangle",
            "to_world": look_at_rectangle(mi, origin, c, (w * radius, h * radius)),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": rgb}},
        }
    return out


def environment_map(width: int = 512) -> np.ndarray:
    """The procedural studio HDR (H = width / 2, W, 3), float32, y up, row 0 at the zenith.

    Same lat-long convention as :func:`kesbrdf.render.scenes.environment_bitmap`
    (Mitsuba's ``envmap``: u = atan2(x, −z) / 2π, v = θ / π).  Made once per width (~0.45 s
    of NumPy; every studio scene loads it: each still, colourway tile and batch preview),
    and returned as a copy the caller may change.
    """
    return _environment_map(int(width)).copy()


@functools.lru_cache(maxsize=2)
def _environment_map(width: int) -> np.ndarray:
    h = width // 2
    theta = (np.arange(h) + 0.5) / h * math.pi
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    up = d[..., 1]
    # room: floor, walls, ceiling blended smoothly by elevation
    wall = 0.012
    base = np.where(up < 0, 0.008 + (wall - 0.008) * np.exp(-((up / 0.15) ** 2)),
                    0.01 + (wall - 0.01) * np.exp(-((up / 0.3) ** 2)))
    img = np.repeat(base[..., None], 3, axis=-1) * np.array([1.0, 0.99, 0.97])

    def softbox(direction, half_w, half_h, radiance, softness=0.02):
        n = np.asarray(direction, float)
        n /= np.linalg.norm(n)
        a = np.cross(n, [0.0, 1.0, 0.0])
        if np.linalg.norm(a) < 1e-6:
            a = np.array([1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(a, n)
        cos_n = d @ n
        # gnomonic coordinates on the box's plane, smooth edges
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(cos_n > 0, (d @ a) / cos_n, 1e9)
            y = np.where(cos_n > 0, (d @ b) / cos_n, 1e9)
        def edge(v, half):  # logistic step, 1 inside the box, argument clipped (no overflow)
            return 1.0 / (1.0 + np.exp(np.minimum((np.abs(v) - half) / softness, 60.0)))

        return radiance * edge(x, half_w) * edge(y, half_h)

    boxes = (softbox((-0.35, 1.0, 0.25), 0.35, 0.25, 1.2) + softbox((0.4, 1.0, -0.3), 0.3, 0.3, 0.9)
             + softbox((0.1, 0.15, 1.0), 0.05, 0.45, 1.0))
    for direction, half_w, half_h, radiance in WINDOWS:
        boxes = boxes + softbox(direction, half_w, half_h, radiance, softness=0.01)
    img = img + boxes[..., None] * np.array([1.0, 0.98, 0.95])
    return img.astype(np.float32)

