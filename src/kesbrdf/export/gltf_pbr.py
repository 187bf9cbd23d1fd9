r"""glTF 2.0 metallic-roughness BRDF with KHR_materials_anisotropy, _sheen, _specular and _ior.

A numpy implementation of the BRDF the ratified extension texts define, used as the
target model of :func:`kesbrdf.export.analytic_fit.fit_analytic`:

.. math::
    \alpha = r^2,\quad \alpha_t = \mathrm{mix}(\alpha, 1, s^2),\quad \alpha_b = \alpha
    \qquad\text{(KHR_materials_anisotropy, normative)}

    F = F_0 + (F_{90} - F_0)(1 - |v\cdot h|)^5,\quad
    F_0 = \min(0.04\,c_{spec}, 1)\,k_{spec},\quad F_{90} = k_{spec}
    \qquad\text{(KHR_materials_specular; 0.04 = ((\eta-1)/(\eta+1))^2, KHR_materials_ior \eta = 1.5)}

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

from kesbrdf.export.analytic_fit import ParamSpec
from kesbrdf.export.microfacet import (
    charlie_albedo,
    charlie_ndf,
    charlie_visibility,
    ggx_anisotropic_ndf,
    ggx_anisotropic_visibility,
    half_vector,
    schlick_weight,
    tangent_frame,
)

__all__ = ["GltfPbr", "GLTF_PBR", "gltf_brdf", "material_json", "specular_f0", "equivalent_ior", "SHEEN_ROUGHNESS_MIN", "EXTENSIONS", "IOR"]

#: sheenRoughness is fitted in [this, 1]: below it the Charlie lobe (exponent 1/r)
#: is a spike at grazing that no measurement grid resolves.
SHEEN_ROUGHNESS_MIN = 0.1
#: roughness lower bound of the fit (α = 0.0004: far sharper than any fabric highlight).
ROUGHNESS_MIN = 0.02
#: The dielectric's index of refraction, fixed in the fit and written as
#: ``KHR_materials_ior``.  1.5 is both the glTF default and the refractive index of
#: textile fibres (η ≈ 1.5, ``kesbrdf.prior.THETA_D_ETA``; a test keeps them equal).
#: The per-channel F0 the fit needs is carried by ``specularColorFactor`` instead.
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
    """
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    base_color = np.atleast_1d(np.asarray(base_color, float))
    specular_color = np.atleast_1d(np.asarray(specular_color, float))
    sheen_color = np.atleast_1d(np.asarray(sheen_color, float))
    nl = wi[..., 2]
    nv = wr[..., 2]
    above = (nl > 0) & (nv > 0)
    nl_s = np.where(above, nl, 1.0)
    nv_s = np.where(above, nv, 1.0)
    h = half_vector(wi, wr)
    # specular lobe: anisotropic GGX (KHR_materials_anisotropy)
    alpha = roughness**2
    s2 = anisotropy_strength**2
    alpha_t = alpha * (1 - s2) + s2
    alpha_b = alpha
    t, b = tangent_frame(anisotropy_rotation)
    D = ggx_anisotropic_ndf(h, t, b, alpha_t, alpha_b)
    V = ggx_anisotropic_visibility(wi, wr, t, b, alpha_t, alpha_b)
    # Fresnel (KHR_materials_specular with the KHR_materials_ior index)
    vh = np.sum(wr * h, axis=-1)
    fw = schlick_weight(vh)[..., None]
    f0 = np.minimum(((ior - 1) / (ior + 1)) ** 2 * specular_color, 1.0) * specular
    F = f0 + (specular - f0) * fw
    DV = (D * V)[..., None]
    dielectric = F * DV + (1 - _max3(F))[..., None] * base_color / np.pi
    metal = (base_color + (1 - base_color) * fw) * DV
    base = dielectric * (1 - metallic) + metal * metallic
    # sheen layer with albedo scaling (KHR_materials_sheen)
    r = max(sheen_roughness, 1e-3) ** 2
    sheen = sheen_color * (charlie_ndf(h[..., 2], r) * charlie_visibility(nl_s, nv_s, r))[..., None]
    smax = _max3(sheen_color)
    scale = np.minimum(1 - smax * charlie_albedo(nv_s, sheen_roughness), 1 - smax * charlie_albedo(nl_s, sheen_roughness))
    f = sheen + base * scale[..., None]
    return np.where(above[..., None], f, 0.0)


class GltfPbr:
    """glTF metallic-roughness + anisotropy + sheen + specular, as an analytic fit target.

    Fitted: baseColor (per channel), roughness, anisotropyStrength, anisotropyRotation,
    specularFactor, specularColorFactor (per channel, up to 1/0.04 = 25 so that F0 can
    reach 1), sheenColorFactor (per channel), sheenRoughnessFactor.  Fixed: metallic 0,
    ior = :data:`IOR` (written as ``KHR_materials_ior``).
    """

    name = "gltf_pbr"
    rotation = "anisotropy_rotation"
    albedo_params = ("base_color",)

    def param_specs(self):
        return [
            ParamSpec("base_color", 0.0, 1.0, 0.3, "color"),
            ParamSpec("roughness", ROUGHNESS_MIN, 1.0, 0.5),
            ParamSpec("anisotropy_strength", 0.0, 1.0, 0.5),
            ParamSpec("anisotropy_rotation", -math.pi / 2, math.pi, 0.0),
            ParamSpec("specular", 0.0, 1.0, 1.0),
            ParamSpec("specular_color", 0.0, 25.0, 1.0, "color"),
            ParamSpec("sheen_color", 0.0, 1.0, 0.1, "color"),
            ParamSpec("sheen_roughness", SHEEN_ROUGHNESS_MIN, 1.0, 0.5),
        ]

    def rotation_basins(self):
        return ((0.0, -math.pi / 2, math.pi / 2), (math.pi / 2, 0.0, math.pi))

    def evaluate(self, p, wi, wr):
        return gltf_brdf(
            wi,
            wr,
            p["base_color"],
            p["roughness"],
            p["anisotropy_strength"],
            p["anisotropy_rotation"],
            p["specular"],
            p["specular_color"],
            p["sheen_color"],
            p["sheen_roughness"],
            ior=IOR,
        )

    def canonical(self, p):
        p = dict(p)
        # the lobe is symmetric under ρ → ρ + π; with zero strength ρ is arbitrary
        p["anisotropy_rotation"] = float(np.mod(p["anisotropy_rotation"], math.pi))
        return p


GLTF_PBR = GltfPbr()


def _rgb(v) -> list[float]:
    v = np.atleast_1d(np.asarray(v, float))
    if v.size == 1:
        v = np.repeat(v, 3)
    return [float(a) for a in v[:3]]


def specular_f0(params: dict, ior: float = IOR) -> list[float]:
    r"""Normal-incidence reflectance F0 per channel of fitted parameters (KHR_materials_specular).

    :math:`F_0 = \min(((\eta-1)/(\eta+1))^2\,c_s, 1)\,s` with c_s = specularColorFactor
    and s = specularFactor.
    """
    c = np.asarray(_rgb(params["specular_color"]))
    return [float(a) for a in np.minimum(((ior - 1) / (ior + 1)) ** 2 * c, 1.0) * float(params["specular"])]


def equivalent_ior(f0) -> list[float]:
    r"""The index a plain dielectric would need for reflectance F0: :math:`(1+\sqrt{F_0})/(1-\sqrt{F_0})`.

    Informative only (``extras``): the written material keeps ior = :data:`IOR` and
    carries F0 in ``specularColorFactor``; F0 ≥ 1 has no finite index (None).
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
                "specularFactor": float(params["specular"]),
                "specularColorFactor": _rgb(params["specular_color"]),
            },
            "KHR_materials_ior": {"ior": IOR},
        },
    }
    if extras is not None:
        material["extras"] = extras
    return material
