"""Post-processing of renders: filmic tone mapping and Open Image Denoise.

Tone mapping
------------
A linear render is turned into an 8-bit sRGB image in three steps:

1. exposure: ``x = 2**exposure · L`` (stops);
2. the **ACES filmic curve** in Krzysztof Narkowicz's rational fit of the ACES
   reference rendering + output transforms (2015), applied per channel:

   .. math::  T(x) = \\frac{x\\,(2.51\\,x + 0.03)}{x\\,(2.43\\,x + 0.59) + 0.14}

   with x pre-scaled by 0.6 as in the fit (so at exposure 0 a linear 0.18 grey
   becomes T(0.108) = 0.140, i.e. sRGB 105/255; linear 1 → 0.67, 10 → 0.993).
   T(0) = 0, T is strictly increasing for x ≥ 0 (its derivative's numerator is
   1.408 x² + 0.703 x + 0.0042 > 0), has a toe below ≈ 0.05 and a shoulder that
   rolls highlights off towards 2.51 / 2.43 ≈ 1.03 (clipped to 1) instead of
   clipping them: a satin highlight ten times brighter than the body keeps its
   shape.  Per-channel application desaturates the brightest highlights towards
   white, as film does; the hue of the body is kept.
3. the sRGB transfer function (IEC 61966-2-1) and rounding to 8 bits.

``curve="clip"`` skips step 2 (the linear clip kesbrdf used before).

Denoising
---------
:func:`denoise` runs Intel Open Image Denoise (``pyoidn``, the ``RT`` filter in HDR
mode) on the linear colour, guided by the first-hit **albedo** and **shading normal**
AOVs (Mitsuba's ``aov`` integrator: ``albedo`` and ``sh_normal``), which keep the
edges of folds and the texture of the body sharp while the noise of the lobe's
Monte Carlo estimate goes.  The AOVs are themselves noisy at low spp (antialiased
edges, the glossy lobe's albedo), so they are prefiltered by OIDN
(``clean_aux=False``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CURVES", "aces_filmic", "aces_inverse", "exposure_for", "tonemap", "to_srgb8", "denoise", "srgb_encode",
           "srgb_decode", "WHITE_POINT"]

CURVES = ("aces", "clip")
#: Pre-scale of Narkowicz's fit (the ACES transform's exposure relative to the fit).
ACES_PRESCALE = 0.6


def aces_filmic(x) -> np.ndarray:
    """Narkowicz's ACES fit T(0.6 x) per channel, for linear x ≥ 0 (negatives → 0)."""
    x = np.maximum(np.asarray(x, np.float64), 0.0) * ACES_PRESCALE
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def aces_inverse(y) -> np.ndarray:
    """The linear x ≥ 0 with :func:`aces_filmic` (x) = y, for display values 0 ≤ y < 1.

    T(u) = y with u = 0.6 x is the quadratic (2.51 − 2.43 y) u² + (0.03 − 0.59 y) u − 0.14 y = 0,
    whose positive root is taken (its other root is ≤ 0 for y ≥ 0).
    """
    y = np.clip(np.asarray(y, np.float64), 0.0, 1.0 - 1e-9)
    a = 2.51 - 2.43 * y
    b = 0.03 - 0.59 * y
    c = -0.14 * y
    u = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    return u / ACES_PRESCALE


#: The curve's white point: the linear value (after exposure) shown as display 1.0
#: (T(0.6 x) reaches 1 at x = 12.07, the root of 0.08 u² − 0.56 u − 0.14 = 0 over 0.6;
#: above it the channel clips).  Relative to a metered grey card (which sits at
#: :func:`aces_inverse` (0.18) = 0.217 after exposure) that is 55.6 × the card's
#: radiance, 5.8 stops above it: a satin highlight up to ~55 × middle grey keeps a
#: gradient instead of a flat white patch.
WHITE_POINT = float(aces_inverse(1.0 - 1e-9))


def exposure_for(card_radiance: float, target: float = 0.18, curve: str = "aces") -> float:
    """Exposure (stops) at which a reference of linear radiance ``card_radiance`` is
    displayed at the linear display value ``target`` (0.18: a grey card reads 18 %).

    The display value is that after the tone curve and before the sRGB encoding, i.e.
    the sRGB-decoded pixel: 0.18 is sRGB 118/255.
    """
    if not (card_radiance > 0 and np.isfinite(card_radiance)):
        raise ValueError(f"exposure metering: expected a positive reference radiance, got {card_radiance!r}")
    x = float(aces_inverse(target)) if curve == "aces" else float(target)
    return float(np.log2(x / card_radiance))


def srgb_decode(v) -> np.ndarray:
    """The inverse of :func:`srgb_encode` (8-bit values / 255 → linear display value)."""
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def srgb_encode(x) -> np.ndarray:
    """The sRGB opto-electronic transfer function on [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(img, exposure: float = 0.0, curve: str = "aces") -> np.ndarray:
    """Linear RGB → display-referred [0, 1] (before the sRGB encoding)."""
    if curve not in CURVES:
        raise ValueError(f"tone curve: expected one of {', '.join(CURVES)}, got {curve!r}")
    x = np.nan_to_num(np.asarray(img, np.float64), nan=0.0, posinf=0.0, neginf=0.0) * (2.0 ** exposure)
    return aces_filmic(x) if curve == "aces" else np.clip(x, 0.0, 1.0)


def to_srgb8(img, exposure: float = 0.0, curve: str = "aces") -> np.ndarray:
    """Linear RGB → 8-bit sRGB through :func:`tonemap`."""
    return (srgb_encode(tonemap(img, exposure, curve)) * 255 + 0.5).astype(np.uint8)


def denoise(color, albedo=None, normal=None, quality: str = "high") -> np.ndarray:
    """Open Image Denoise (``pyoidn``) on a linear HDR image (H, W, 3).

    ``albedo`` (H, W, 3) in [0, 1] and ``normal`` (H, W, 3) in [−1, 1] guide the
    filter; either may be None (OIDN then denoises from the colour alone, but a normal
    needs an albedo).  Returns a new float32 array.
    """
    try:
        import pyoidn
    except ImportError as exc:  # pragma: no cover - optional dependency
        raise ImportError(f"denoising needs pyoidn ({exc}); install kesbrdf[render]") from None
    c = np.ascontiguousarray(np.nan_to_num(np.maximum(color, 0.0)), np.float32)
    a = None if albedo is None else np.ascontiguousarray(np.clip(albedo, 0.0, 1.0), np.float32)
    n = None
    if normal is not None and a is not None:
        n = np.asarray(normal, np.float32)
        length = np.linalg.norm(n, axis=-1, keepdims=True)
        n = np.ascontiguousarray(np.where(length > 1e-6, n / np.maximum(length, 1e-6), 0.0), np.float32)
    return np.asarray(pyoidn.denoise(c, a, n, hdr=True, quality=quality), np.float32)
