r"""glTF 2.0 metallic-roughness BRDF with KHR_materials_anisotropy, _sheen, _specular and _ior.

A numpy implementation of the BRDF the ratified extension texts define, used as the
target model of :func:`kesbrdf.export.analytic_fit.fit_analytic`:

.. math::
    \alpha = r^2,\quad \alpha_t = \mathrm{mix}(\alpha, 1, s^2),\quad \alpha_b = \alpha
    \qquad\text{(KHR_materials_anisotropy, normative)}

    F = F_0 + (F_{90} - F_0)(1 - |v\cdot h|)^5,\quad
    F_0 = \min(((\eta-1)/(\eta+1))^2\,c_{spec}, 1)\,k_{spec},\quad F_{90} = k_{spec}
    \qquad\text{(KHR_materials_specular with the KHR_materials_ior \eta; } k_{spec} = 1\text{ in fits)}

    f_{base} = F\,V\,D + (1 - \max_c F)\,c_{base}/\pi \qquad\text{(core Appendix B, metallic = 0)}

    f_r = c_{sheen}\,D_c V_c + f_{base}\,\min(1 - \max_c c_{sheen}E(\mu_v), 1 - \max_c c_{sheen}E(\mu_l))
    \qquad\text{(KHR_materials_sheen, albedo scaling)}

with the anisotropic GGX D and height-correlated V of :mod:`.microfacet`, the Charlie
D_c, V_c and their albedo E.  The metal branch of Appendix B is implemented too
(``metallic`` ≠ 0), but fabrics are fitted with metallic fixed at 0.

Tangent convention (documented because implementations disagree, see
``docs/exports.md``): the mesh TANGENT runs along the warp (fabric x), the bitangent
along the weft (y = n × t with w = +1), and the anisotropy direction
t_a = (cos ρ, sin ρ) in that frame, ρ = ``anisotropyRotation`` counter-clockwise from
the tangent about the normal.  Along t_a the roughness is the larger α_t: highlights
stretch along t_a (the grooves run perpendicular to it).
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.export.analytic_fit import FIBRE_IOR_RANGE, ParamSpec
from kesbrdf.export.microfacet import (
    charlie_lambda,
    charlie_albedo,
    charlie_ndf,
    ggx_anisotropic_ndf,
    ggx_anisotropic_visibility,
    pair_geometry,
    schlick_weight,
    tangent_frame,
)

__all__ = [
    "GltfPbr", "GLTF_PBR", "gltf_brdf", "material_json", "specular_f0", "equivalent_ior", "f0_of_ior",
    "ior_and_color_of_f0", "SHEEN_ROUGHNESS_MIN", "EXTENSIONS", "IOR", "F0_RANGE",
]

#: sheenRoughness is fitted in [this, 1]: below it the Charlie lobe (exponent 1/r)
#: is a spike at grazing that no measurement grid resolves.
SHEEN_ROUGHNESS_MIN = 0.1
#: roughness lower bound of the fit (α = 0.0004: far sharper than any fabric highlight).
ROUGHNESS_MIN = 0.02
#: The dielectric's index of refraction where the fit starts (and the value of a
#: parameter set without ``ior``): both the glTF default and the refractive index of
#: textile fibres (η ≈ 1.5, ``kesbrdf.models.fibre_physics.THETA_D_ETA``; a test keeps them equal).
#: The fit moves it within :data:`~kesbrdf.export.analytic_fit.FIBRE_IOR_RANGE` and
#: writes it as ``KHR_materials_ior``; ``specularColorFactor`` ≤ 1 tints the F0 it gives.
IOR = 1.5
EXTENSIONS = ("KHR_materials_anisotropy", "KHR_materials_sheen", "KHR_materials_specular", "KHR_materials_ior")


def _max3(c):
    return np.max(np.atleast_1d(c), axis=-1)


def gltf_brdf(
    wi,
    wr,
    base_color,
    roughness,
    anisotropy_strength=0.0,
    anisotropy_rotation=0.0,
    specular=1.0,
    specular_color=(1.0,),
    sheen_color=(0.0,),
    sheen_roughness=0.5,
    metallic=0.0,
    ior=IOR,
    geo=None,
):
    """f_r (1/sr) of a glTF material, shape (N, C) with C = len(base_color).

    Parameters
    ----------
    wi, wr : ndarray, shape (N, 3)
        To the light and to the viewer, shading frame (x = mesh tangent, z = normal).
    base_color, specular_color, sheen_color : array_like, shape (C,) or scalar
        Linear colours (``baseColorFactor`` RGB, ``specularColorFactor``, ``sheenColorFactor``).
    roughness, anisotropy_strength, anisotropy_rotation, specular, sheen_roughness, metallic, ior
        The glTF factors (radians for the rotation).
    geo : PairGeometry, optional
        :func:`kesbrdf.export.microfacet.pair_geometry` of (wi, wr), when already computed.
    """
    g = geo if geo is not None else pair_geometry(wi, wr)
    wi, wr, h = g.wi, g.wr, g.h
    base_color = np.atleast_1d(np.asarray(base_color, float))
    specular_color = np.atleast_1d(np.asarray(specular_color, float))
    sheen_color = np.atleast_1d(np.asarray(sheen_color, float))
    above = g.above
    nl_s = np.where(above, g.cos_i, 1.0)
    nv_s = np.where(above, g.cos_r, 1.0)
    # specular lobe: anisotropic GGX (KHR_materials_anisotropy)
    alpha = roughness**2
    s2 = anisotropy_strength**2
    alpha_t = alpha * (1 - s2) + s2
    alpha_b = alpha
    t, b = tangent_frame(anisotropy_rotation)
    D = ggx_anisotropic_ndf(h, t, b, alpha_t, alpha_b)
    V = ggx_anisotropic_visibility(wi, wr, t, b, alpha_t, alpha_b)
    # Fresnel (KHR_materials_specular with the KHR_materials_ior index)
    fw = schlick_weight(g.cos_vh)[..., None]
    f0 = np.minimum(((ior - 1) / (ior + 1)) ** 2 * specular_color, 1.0) * specular
    F = f0 + (specular - f0) * fw
    DV = (D * V)[..., None]
    dielectric = F * DV + (1 - _max3(F))[..., None] * base_color / np.pi
    if metallic:
        metal = (base_color + (1 - base_color) * fw) * DV
        base = dielectric * (1 - metallic) + metal * metallic
    else:
        base = dielectric
    # sheen layer with albedo scaling (KHR_materials_sheen)
    smax = _max3(sheen_color)
    if np.all(smax == 0.0):
        return np.where(above[..., None], base, 0.0)
    r = max(sheen_roughness, 1e-3) ** 2
    # Λ and E depend on one cosine each: evaluated once per distinct cos θ (PairGeometry)
    lam = lambda mu: charlie_lambda(np.where(mu > 0, mu, 1.0), r)  # noqa: E731
    V_c = 1.0 / ((1.0 + g.on_cos_r(lam) + g.on_cos_i(lam)) * (4.0 * nv_s * nl_s))
    sheen = sheen_color * (charlie_ndf(g.cos_h, r) * V_c)[..., None]
    albedo = lambda mu: charlie_albedo(np.where(mu > 0, mu, 1.0), sheen_roughness)  # noqa: E731
    scale = np.minimum(1 - smax * g.on_cos_r(albedo), 1 - smax * g.on_cos_i(albedo))
    f = sheen + base * scale[..., None]
    return np.where(above[..., None], f, 0.0)


def f0_of_ior(ior):
    """F0 = ((η − 1)/(η + 1))² of a dielectric of index η."""
    ior = np.asarray(ior, float)
    return ((ior - 1.0) / (ior + 1.0)) ** 2


#: F0 at the ends of the fibre index range: 1.7 % and 8.2 %
F0_RANGE = (float(f0_of_ior(FIBRE_IOR_RANGE[0])), float(f0_of_ior(FIBRE_IOR_RANGE[1])))


def ior_and_color_of_f0(f0) -> tuple[float, np.ndarray]:
    """(ior, specularColorFactor) that give the per-channel F0 with specularFactor 1.

    The brightest channel sets the index, (1 + √F0)/(1 − √F0) (at least the fibre
    minimum 1.3), and the colour (≤ 1) tints the others: F0_c = ((η−1)/(η+1))²·c_c.
    """
    f0 = np.clip(np.atleast_1d(np.asarray(f0, float)), 0.0, F0_RANGE[1])
    top = float(np.max(f0))
    if top <= F0_RANGE[0]:
        return FIBRE_IOR_RANGE[0], f0 / F0_RANGE[0]
    r = math.sqrt(top)
    ior = min(max((1 + r) / (1 - r), FIBRE_IOR_RANGE[0]), FIBRE_IOR_RANGE[1])  # exact ends despite rounding
    return ior, f0 / top


class GltfPbr:
    """glTF metallic-roughness + anisotropy + sheen + specular + ior, as an analytic fit target.

    Fitted, each within its physical range: baseColor [0, 1] per channel, roughness
    [:data:`ROUGHNESS_MIN`, 1], anisotropyStrength [0, 1], anisotropyRotation, the
    specular F0 per channel in [0, 8.2 %] (written as ``KHR_materials_ior`` in textile
    fibres' range :data:`~kesbrdf.export.analytic_fit.FIBRE_IOR_RANGE` and
    ``specularColorFactor`` ≤ 1: :func:`ior_and_color_of_f0`; the two alone would be
    redundant, F0 = ((η−1)/(η+1))²·c), sheenColorFactor [0, 1] per channel,
    sheenRoughnessFactor [:data:`SHEEN_ROUGHNESS_MIN`, 1].  Fixed: metallic 0 and
    specularFactor 1, so that F90 = 1 as in every importer: Blender maps specularFactor
    to "Specular IOR Level", which lowers F0 but never F90, and a specularColorFactor
    above 1 to a "Specular Tint" above 1 (docs/exports.md).
    """

    name = "gltf_pbr"
    rotation = "anisotropy_rotation"
    albedo_params = ("base_color",)
    #: colour parameters that act on other channels too (through max over channels)
    coupled_colors = ("specular_f0", "sheen_color")

    def param_specs(self):
        return [
            ParamSpec("base_color", 0.0, 1.0, 0.3, "color"),
            ParamSpec("roughness", ROUGHNESS_MIN, 1.0, 0.5),
            ParamSpec("anisotropy_strength", 0.0, 1.0, 0.5, report_lo=False),
            ParamSpec("anisotropy_rotation", -math.pi / 2, math.pi, 0.0),
            ParamSpec("specular_f0", 0.0, F0_RANGE[1], float(f0_of_ior(IOR)), "color"),
            ParamSpec("sheen_color", 0.0, 1.0, 0.1, "color", report_lo=False),
            ParamSpec("sheen_roughness", SHEEN_ROUGHNESS_MIN, 1.0, 0.5, lobe="sheen_color"),
        ]

    def report_specs(self):
        """The ranges of the written parameters, for :func:`~kesbrdf.export.analytic_fit.bounds_hit`."""
        specs = [s for s in self.param_specs() if s.name != "specular_f0"]
        return specs + [ParamSpec("ior", FIBRE_IOR_RANGE[0], FIBRE_IOR_RANGE[1], IOR)]

    def rotation_basins(self):
        return ((0.0, -math.pi / 2, math.pi / 2), (math.pi / 2, 0.0, math.pi))

    def evaluate(self, p, wi, wr, geo=None):
        if "specular_f0" in p:
            ior, specular_color = ior_and_color_of_f0(p["specular_f0"])
        else:
            ior, specular_color = p.get("ior", IOR), p["specular_color"]
        return gltf_brdf(
            wi,
            wr,
            p["base_color"],
            p["roughness"],
            p["anisotropy_strength"],
            p["anisotropy_rotation"],
            p.get("specular", 1.0),
            specular_color,
            p["sheen_color"],
            p["sheen_roughness"],
            ior=ior,
            geo=geo,
        )

    def canonical(self, p):
        p = dict(p)
        # the lobe is symmetric under ρ → ρ + π; with zero strength ρ is arbitrary
        p["anisotropy_rotation"] = float(np.mod(p["anisotropy_rotation"], math.pi))
        if "specular_f0" in p:
            p["ior"], p["specular_color"] = ior_and_color_of_f0(p.pop("specular_f0"))
        p["specular"] = 1.0
        return p


GLTF_PBR = GltfPbr()


def _rgb(v) -> list[float]:
    v = np.atleast_1d(np.asarray(v, float))
    if v.size == 1:
        v = np.repeat(v, 3)
    return [float(a) for a in v[:3]]


def specular_f0(params: dict, ior: float | None = None) -> list[float]:
    r"""Normal-incidence reflectance F0 per channel of fitted parameters (KHR_materials_specular).

    :math:`F_0 = \min(((\eta-1)/(\eta+1))^2\,c_s, 1)\,s` with c_s = specularColorFactor,
    s = specularFactor and η = ``ior`` (default: the parameters' own ``ior``, else :data:`IOR`).
    """
    ior = float(params.get("ior", IOR)) if ior is None else float(ior)
    c = np.asarray(_rgb(params["specular_color"]))
    return [float(a) for a in np.minimum(((ior - 1) / (ior + 1)) ** 2 * c, 1.0) * float(params.get("specular", 1.0))]


def equivalent_ior(f0) -> list[float]:
    r"""The index a plain dielectric would need for reflectance F0: :math:`(1+\sqrt{F_0})/(1-\sqrt{F_0})`.

    Informative only (``extras``): the written material carries its fitted ior and the
    tint of F0 in ``specularColorFactor``; F0 ≥ 1 has no finite index (None).
    """
    out = []
    for f in np.atleast_1d(np.asarray(f0, float)):
        r = math.sqrt(max(float(f), 0.0))
        out.append(float((1 + r) / (1 - r)) if r < 1 else None)
    return out


def material_json(params: dict, name: str = "kesbrdf_fabric", extras: dict | None = None) -> dict:
    """The glTF ``material`` object (core + four extensions) of fitted parameters."""
    base = _rgb(params["base_color"])
    material = {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": base + [1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": float(params["roughness"]),
        },
        "extensions": {
            "KHR_materials_anisotropy": {
                "anisotropyStrength": float(params["anisotropy_strength"]),
                "anisotropyRotation": float(params["anisotropy_rotation"]),
            },
            "KHR_materials_sheen": {
                "sheenColorFactor": _rgb(params["sheen_color"]),
                "sheenRoughnessFactor": float(params["sheen_roughness"]),
            },
            "KHR_materials_specular": {
                "specularFactor": float(params.get("specular", 1.0)),
                "specularColorFactor": _rgb(params["specular_color"]),
            },
            "KHR_materials_ior": {"ior": float(params.get("ior", IOR))},
        },
    }
    if extras is not None:
        material["extras"] = extras
    return material
