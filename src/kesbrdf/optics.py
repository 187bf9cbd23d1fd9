r"""Fresnel reflectance: the one implementation every model, reference, renderer and export uses.

Unpolarised Fresnel reflectance of a smooth dielectric of relative index η seen from air
(Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces", eq. 22):

.. math::

    F(c) = \frac12 \frac{(g - c)^2}{(g + c)^2}
           \left(1 + \frac{\bigl(c(g + c) - 1\bigr)^2}{\bigl(c(g - c) + 1\bigr)^2}\right),
    \qquad g = \sqrt{\eta^2 - 1 + c^2},\quad c = |\cos\theta|

It equals ½(r_s² + r_p²) of the Fresnel equations; F(1) = ((η − 1)/(η + 1))² and
F(0) = 1.  Schlick's approximation F ≈ F_0 + (1 − F_0)(1 − c)⁵ is given by its weight
(1 − c)⁵ (:func:`schlick_weight`).

Both functions take an array module ``xp``: numpy (default) or ``drjit``, so the
Dr.Jit BSDFs of :mod:`kesbrdf.render` evaluate the same expression as the numpy code.
"""

from __future__ import annotations

import numpy as np

__all__ = ["fresnel_dielectric", "schlick_weight"]


def fresnel_dielectric(cos_theta, eta: float, xp=np):
    """Unpolarised Fresnel reflectance from air into a dielectric of index ``eta`` ≥ 1.

    ``cos_theta`` counts by its absolute value (module docstring).

    >>> round(float(fresnel_dielectric(1.0, 1.5)), 12), float(fresnel_dielectric(0.0, 1.5))
    (0.04, 1.0)
    """
    if xp is np:
        cos_theta = np.asarray(cos_theta, float)
    c = xp.clip(xp.abs(cos_theta), 0.0, 1.0)
    g = xp.sqrt(xp.maximum(eta * eta - 1.0 + c * c, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def schlick_weight(cos_theta, xp=np):
    """(1 − |cos θ|)⁵, the weight of Schlick's Fresnel approximation.

    >>> float(schlick_weight(1.0)), float(schlick_weight(0.0))
    (0.0, 1.0)
    """
    if xp is np:
        cos_theta = np.asarray(cos_theta, float)
    return xp.power(1.0 - xp.clip(xp.abs(cos_theta), 0.0, 1.0), 5.0)
