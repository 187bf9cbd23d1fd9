r"""OpenPBR Surface (v1.1) reflection lobes in numpy, as an analytic fit target.

The subset a fabric uses: an opaque dielectric base (diffuse + anisotropic GGX
specular) under a fuzz layer.  Following the MaterialX 1.39 reference graph
``NG_open_pbr_surface_surfaceshader``:

.. math::
    f_r = w_f c_f\,f_{fuzz} + (1 - w_f E_{fuzz}(\mu_v))\,
          \bigl[c_s F(v\cdot h)\,D\,V + (1 - E_{spec}(\mu_v))\,c_b/\pi\bigr]

- specular: anisotropic GGX with OpenPBR's mapping of ``specular_roughness`` r and
  ``specular_roughness_anisotropy`` a (``ND_open_pbr_anisotropy``):
  α_t = r²·√(2/(1 + (1 − a)²)), α_b = (1 − a)·α_t, stretched along the tangent, which
  the export rotates by ρ about the normal (``geometry_tangent`` through ``rotate3d``:
  OpenPBR has no rotation input).  F is the exact dielectric Fresnel of
  ``specular_ior`` tinted by ``specular_color`` (``specular_weight`` = 1).
- base: Lambert (``base_diffuse_roughness`` = 0), colour ``base_color``, weight 1.
- fuzz: MaterialX ``sheen_bsdf mode="zeltner"`` (the LTC fit of Zeltner et al. 2022),
  with MaterialX's layer throughput 1 − w_f·E_fuzz(μ_v).

Approximated (documented in docs/exports.md): the specular layer throughput
1 − E_spec uses MaterialX's closed-form GGX albedo fit at the mean α = √(α_t α_b)
without the multiple-scattering compensation term, and the shadowing is the
anisotropic height-correlated Smith term (MaterialX uses the isotropic G₂ at the
mean α).  Renderers that implement OpenPBR's energy-conserving layering exactly will
differ by a few percent in the diffuse part.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.export.analytic_fit import FIBRE_IOR_RANGE, ParamSpec
from kesbrdf.export.microfacet import (
    fresnel_dielectric,
    ggx_anisotropic_ndf,
    ggx_anisotropic_visibility,
    ggx_directional_albedo,
    pair_geometry,
    tangent_frame,
    zeltner_sheen,
    zeltner_sheen_albedo,
)

__all__ = ["OpenPbr", "OPENPBR", "openpbr_alphas", "IOR_RANGE"]

#: specular_ior is fitted in textile fibres' range (F0 = 1.7–8.2 %): a wider range lets
#: the fit buy a bright highlight with a mirror-like F0 (an index of 5 gives F0 = 0.44).
IOR_RANGE = FIBRE_IOR_RANGE


def openpbr_alphas(roughness, anisotropy):
    """(α_t, α_b) of ``ND_open_pbr_anisotropy``."""
    alpha = roughness**2
    alpha_t = alpha * np.sqrt(2.0 / (1.0 + (1.0 - anisotropy) ** 2))
    return np.minimum(alpha_t, 1.0), (1.0 - anisotropy) * np.minimum(alpha_t, 1.0)


def dielectric_specular(wi, wr, alpha_t, alpha_b, rotation, ior, specular_color, geo=None):
    """Tinted dielectric anisotropic GGX lobe and its layer throughput 1 − E_spec(μ_v).

    Returns
    -------
    spec : ndarray, shape (N, C)
    throughput : ndarray, shape (N, 1)
    """
    g = geo if geo is not None else pair_geometry(wi, wr)
    wi, wr, h = g.wi, g.wr, g.h
    t, b = tangent_frame(rotation)
    DV = ggx_anisotropic_ndf(h, t, b, alpha_t, alpha_b) * ggx_anisotropic_visibility(wi, wr, t, b, alpha_t, alpha_b)
    F = fresnel_dielectric(g.cos_vh, ior)
    spec = np.atleast_1d(specular_color) * (F * DV)[..., None]
    f0 = ((ior - 1) / (ior + 1)) ** 2
    alpha = np.sqrt(alpha_t * alpha_b)
    E = g.on_cos_r(lambda mu: ggx_directional_albedo(np.clip(mu, 1e-6, 1.0), alpha, np.asarray([f0]), np.asarray([1.0])))
    return spec, 1.0 - E


class OpenPbr:
    """OpenPBR Surface: base_color, specular_roughness, specular_roughness_anisotropy,
    tangent rotation ρ, specular_ior, specular_color, fuzz_weight, fuzz_color, fuzz_roughness."""

    name = "openpbr"
    rotation = "tangent_rotation"
    albedo_params = ("base_color",)

    def param_specs(self):
        return [
            ParamSpec("base_color", 0.0, 1.0, 0.3, "color"),
            ParamSpec("specular_roughness", 0.02, 1.0, 0.5),
            ParamSpec("specular_roughness_anisotropy", 0.0, 0.98, 0.5, report_lo=False),
            ParamSpec("tangent_rotation", -math.pi / 2, math.pi, 0.0),
            ParamSpec("specular_ior", IOR_RANGE[0], IOR_RANGE[1], 1.5),
            ParamSpec("specular_color", 0.0, 1.0, 1.0, "color"),
            ParamSpec("fuzz_weight", 0.0, 1.0, 0.3, report_lo=False),
            ParamSpec("fuzz_color", 0.0, 1.0, 0.5, "color", report_lo=False, lobe="fuzz_weight"),
            ParamSpec("fuzz_roughness", 0.01, 1.0, 0.5, lobe="fuzz_weight"),
        ]

    def rotation_basins(self):
        return ((0.0, -math.pi / 2, math.pi / 2), (math.pi / 2, 0.0, math.pi))

    def evaluate(self, p, wi, wr, geo=None):
        g = geo if geo is not None else pair_geometry(wi, wr)
        wi, wr, above = g.wi, g.wr, g.above
        alpha_t, alpha_b = openpbr_alphas(p["specular_roughness"], p["specular_roughness_anisotropy"])
        spec, through_spec = dielectric_specular(wi, wr, alpha_t, alpha_b, p["tangent_rotation"], p["specular_ior"], p["specular_color"], g)
        diffuse = through_spec * np.atleast_1d(p["base_color"]) / np.pi
        w_f = p["fuzz_weight"]
        fuzz = w_f * np.atleast_1d(p["fuzz_color"]) * zeltner_sheen(wi, wr, p["fuzz_roughness"])[..., None]
        E_fuzz = g.on_cos_r(lambda mu: zeltner_sheen_albedo(np.clip(mu, 1e-6, 1.0), p["fuzz_roughness"]))
        through = (1.0 - w_f * E_fuzz)[..., None]
        f = fuzz + through * (spec + diffuse)
        return np.where(above[..., None], f, 0.0)

    def canonical(self, p):
        p = dict(p)
        p["tangent_rotation"] = float(np.mod(p["tangent_rotation"], math.pi))
        return p


OPENPBR = OpenPbr()
