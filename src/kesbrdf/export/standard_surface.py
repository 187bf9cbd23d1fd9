r"""Autodesk Standard Surface reflection lobes in numpy, as an analytic fit target.

The fabric subset, following the MaterialX 1.39 graph ``NG_standard_surface_surfaceshader_100``
(its layer order: specular over sheen over diffuse):

.. math::
    f_r = c_s F(v\cdot h)\,D\,V + (1 - E_{spec}(\mu_v))\,
          \bigl[w_{sh} c_{sh} f_{iw} + (1 - w_{sh} E_{iw}(\mu_v))\,c_b/\pi\bigr]

- specular: anisotropic GGX with MaterialX ``roughness_anisotropy``:
  α_x = min(r²/√(1 − a), 1), α_y = r²·√(1 − a) (a ≤ 0.98), along the tangent rotated by
  ``specular_rotation`` turns (× 360°) about the normal; exact dielectric Fresnel of
  ``specular_IOR`` tinted by ``specular_color`` (``specular`` weight 1).
- sheen: MaterialX ``sheen_bsdf`` mode "conty_kulla" (Imageworks Charlie NDF with the
  "smoother" 4(n·l + n·v − n·l n·v) denominator) and its rational albedo fit E_iw.
- diffuse: Lambert (``diffuse_roughness`` 0), ``base`` = 1, colour ``base_color``.

Approximated as in :mod:`.openpbr`: the specular layer throughput (closed-form GGX
albedo at the mean α, no multiple-scattering compensation) and the anisotropic
Smith shadowing (MaterialX uses the isotropic G₂ at the mean α).
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.export.analytic_fit import ParamSpec
from kesbrdf.export.microfacet import imageworks_sheen, imageworks_sheen_albedo, pair_geometry
from kesbrdf.export.openpbr import IOR_RANGE, dielectric_specular

__all__ = ["StandardSurface", "STANDARD_SURFACE", "standard_surface_alphas"]


def standard_surface_alphas(roughness, anisotropy):
    """(α_x, α_y) of MaterialX ``roughness_anisotropy``."""
    r2 = np.clip(roughness**2, 1e-6, 1.0)
    aspect = np.sqrt(1.0 - np.clip(anisotropy, 0.0, 0.98))
    return np.minimum(r2 / aspect, 1.0), r2 * aspect


class StandardSurface:
    """Standard Surface: base_color, specular_roughness, specular_anisotropy,
    specular_rotation (turns), specular_IOR, specular_color, sheen, sheen_color, sheen_roughness."""

    name = "standard_surface"
    rotation = "specular_rotation"
    albedo_params = ("base_color",)

    def param_specs(self):
        return [
            ParamSpec("base_color", 0.0, 1.0, 0.3, "color"),
            ParamSpec("specular_roughness", 0.02, 1.0, 0.5),
            ParamSpec("specular_anisotropy", 0.0, 0.98, 0.5, report_lo=False),
            ParamSpec("specular_rotation", -0.25, 0.5, 0.0),
            ParamSpec("specular_IOR", IOR_RANGE[0], IOR_RANGE[1], 1.5),
            ParamSpec("specular_color", 0.0, 1.0, 1.0, "color"),
            ParamSpec("sheen", 0.0, 1.0, 0.3, report_lo=False),
            ParamSpec("sheen_color", 0.0, 1.0, 0.5, "color", report_lo=False, lobe="sheen"),
            ParamSpec("sheen_roughness", 0.05, 1.0, 0.3, lobe="sheen"),
        ]

    def rotation_basins(self):
        # specular_rotation is in turns: 0 and a quarter turn (π/2)
        return ((0.0, -0.25, 0.25), (0.25, 0.0, 0.5))

    def evaluate(self, p, wi, wr, geo=None):
        g = geo if geo is not None else pair_geometry(wi, wr)
        wi, wr, above = g.wi, g.wr, g.above
        alpha_x, alpha_y = standard_surface_alphas(p["specular_roughness"], p["specular_anisotropy"])
        rotation = 2 * math.pi * p["specular_rotation"]
        spec, through_spec = dielectric_specular(wi, wr, alpha_x, alpha_y, rotation, p["specular_IOR"], p["specular_color"], g)
        nl = np.clip(g.cos_i, 1e-6, 1.0)
        nv = np.clip(g.cos_r, 1e-6, 1.0)
        base = np.atleast_1d(p["base_color"]) / np.pi
        w_sh = p["sheen"]
        sheen = w_sh * np.atleast_1d(p["sheen_color"]) * imageworks_sheen(nl, nv, g.cos_h, p["sheen_roughness"])[..., None]
        E_sheen = g.on_cos_r(lambda mu: imageworks_sheen_albedo(np.clip(mu, 1e-6, 1.0), p["sheen_roughness"]))
        through_sheen = (1.0 - w_sh * E_sheen)[..., None]
        f = spec + through_spec * (sheen + through_sheen * base)
        return np.where(above[..., None], f, 0.0)

    def canonical(self, p):
        p = dict(p)
        p["specular_rotation"] = float(np.mod(p["specular_rotation"], 0.5))
        return p


STANDARD_SURFACE = StandardSurface()
