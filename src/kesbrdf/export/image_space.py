r"""Image-space weighting of the analytic fits: compare what a picture of the fabric shows.

An analytic material stands in for the fabric in a picture, so the fits compare
*displayed pixel values*, not BRDF values (plain BRDF residuals are dominated by the
highlight peak and let the body colour of a dark fabric go to zero).  For a pair of
directions (ω_i to the light, ω_r to the viewer):

.. math::
    x = \pi\,f_r(\omega_i, \omega_r)\,\cos\theta_i
    \qquad\text{(exposure: a white Lambertian card facing the light shows } x = 1)

    d(x) = \mathrm{sRGB}\!\left(\frac{x}{1 + x}\right)
    \qquad\text{(Reinhard tone map, then the sRGB transfer curve; } d \in [0, 1))

    w(\omega_i, \omega_r) = \cos\theta_r\;L(\beta),\qquad
    \cos\beta = \omega_i\cdot\omega_r

- x/(1 + x) keeps a highlight many times brighter than white inside the display range
  (so the highlight counts, but does not swamp everything), and the sRGB curve spreads
  the dark values as a screen does (so the body colour of a near-black fabric counts:
  display 0.15 for a 2 % body, 0 for a black one).
- cos θ_r: the image area that shows a surface element seen at θ_r (pixels per dω_r).
- L(β): the light distribution of a typical studio rig, as seen from the surface: the
  angle β between light and viewer is the same at every point of a picture lit by one
  distant light, so the rig is a distribution over β: a dome (constant
  :data:`DOME_WEIGHT`), a key light :data:`KEY_LIGHT` near the camera and a rim light
  :data:`RIM_LIGHT` behind the subject (Gaussian bumps over β; mean of L over the
  hemisphere pairs ≈ 0.84).
- The grids' cells have equal solid angle, so the sums are hemisphere integrals.

The fits minimise Σ w (b_fit − b_ref)² (channels pooled) of the *bracketed* value
b(x) = ½ [d(x) + d(x/8)]: the picture at the studio exposure and three stops under it,
so that a highlight that the tone map squeezes near white at the studio exposure still
counts by its energy (on the Ward test fabric this halves the highlight's NRMSE loss
at the same studio-exposure image error).  :func:`image_rmse` reports the studio
exposure alone, √(Σ w Δd² / Σ w), in display units (0.01 ≈ 2.5 steps of an 8-bit
image).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "display_value",
    "display_value_linear",
    "bracketed_value",
    "UNDER_EXPOSURE",
    "studio_light",
    "pair_weight",
    "image_rmse",
    "DOME_WEIGHT",
    "KEY_LIGHT",
    "RIM_LIGHT",
    "DEFINITION",
]

#: The second exposure of :func:`bracketed_value`: three stops under the studio exposure.
UNDER_EXPOSURE = 1.0 / 8.0
#: Constant part of the light distribution L(β): an environment dome lights every pair.
DOME_WEIGHT = 0.3
#: Key light: (β in degrees, spread σ in degrees, weight); 45° between camera and key.
KEY_LIGHT = (45.0, 25.0, 1.0)
#: Rim (back) light: (β in degrees, σ in degrees, weight): light from behind the subject.
RIM_LIGHT = (150.0, 20.0, 0.5)

DEFINITION = (
    "image RMSE: sqrt(sum w (d_fit - d_ref)^2 / sum w), d = sRGB(x/(1+x)), x = pi f_r cos theta_i, "
    "w = cos theta_r * L(beta), L = dome 0.3 + key (45 deg, sigma 25, 1.0) + rim (150 deg, sigma 20, 0.5), "
    "equal-solid-angle pairs, channels pooled; display units"
)


def display_value_linear(t):
    """The sRGB transfer curve (IEC 61966-2-1) of a linear value t ∈ [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    return np.where(t <= 0.0031308, 12.92 * t, 1.055 * np.power(np.maximum(t, 0.0031308), 1 / 2.4) - 0.055)


def display_value(x):
    """d(x) = sRGB(x / (1 + x)) of the radiance x = π f_r cos θ_i (module docstring)."""
    x = np.maximum(np.asarray(x, float), 0.0)
    return display_value_linear(x / (1.0 + x))


def bracketed_value(x):
    """b(x) = ½ [d(x) + d(x · :data:`UNDER_EXPOSURE`)]: the fits' objective space."""
    x = np.asarray(x, float)
    return 0.5 * (display_value(x) + display_value(x * UNDER_EXPOSURE))


def studio_light(cos_beta):
    """L(β): dome + key + rim weights over the angle β between light and viewer."""
    beta = np.degrees(np.arccos(np.clip(cos_beta, -1.0, 1.0)))
    out = np.full(np.shape(beta), DOME_WEIGHT)
    for b0, sigma, weight in (KEY_LIGHT, RIM_LIGHT):
        out = out + weight * np.exp(-0.5 * ((beta - b0) / sigma) ** 2)
    return out


def pair_weight(wi, wr):
    """w = cos θ_r · L(β) per pair (N,), 0 below either horizon."""
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    above = (wi[..., 2] > 0) & (wr[..., 2] > 0)
    return np.where(above, wr[..., 2] * studio_light(np.sum(wi * wr, axis=-1)), 0.0)


def image_rmse(f_fit, f_ref, wi, wr) -> float:
    """√(Σ w (d_fit − d_ref)² / Σ w) over pairs and channels (display units); NaN pairs skipped."""
    f_fit = np.asarray(f_fit, float)
    f_ref = np.asarray(f_ref, float)
    cos_i = np.asarray(wi, float)[:, 2:3]
    ok = np.isfinite(f_fit) & np.isfinite(f_ref)
    w = pair_weight(wi, wr)[:, None] * ok
    d = display_value(math.pi * np.where(ok, f_fit, 0.0) * cos_i) - display_value(math.pi * np.where(ok, f_ref, 0.0) * cos_i)
    return math.sqrt(float(np.sum(w * d**2)) / max(float(np.sum(w)), 1e-300))
