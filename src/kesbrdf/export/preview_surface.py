r"""UsdPreviewSurface (metallic 0, no clearcoat) in numpy, as an analytic fit target.

The USD export's fallback for renderers without MaterialX (Apple Quick Look, most
viewers): an isotropic material that must look like the fabric's diffuse colour with a
plausible gloss.  It is fitted to the kesbrdf model in its own right, not copied from
the OpenPBR fit (whose anisotropic lobe and fuzz layer it cannot carry).

Following the UsdPreviewSurface specification (roughness squared before use, F0 from
``ior``, ``useSpecularWorkflow`` = 0) and its reference implementation in Storm
(``previewSurface.glslfx``):

.. math::
    \alpha = r^2,\quad F = F_0 + (1 - F_0)(1 - \omega_r\cdot h)^5,\quad
    F_0 = \left(\frac{\eta - 1}{\eta + 1}\right)^2

    D = \frac{\alpha^2}{\pi\,((n\cdot h)^2(\alpha^2 - 1) + 1)^2},\quad
    G = G_1(n\cdot l)\,G_1(n\cdot v),\ G_1(x) = \frac{x}{x(1 - k) + k},\ k = \alpha/2

    f_r = (1 - F)\,\frac{c_d}{\pi} + \frac{F\,G\,D}{4\,(n\cdot l)(n\cdot v)}

(Storm adds ε = 10⁻³ to D's numerator and the denominator; omitted here.)

Fitted, each within its physical range: ``diffuseColor`` [0, 1] per channel,
``roughness`` [:data:`ROUGHNESS_MIN`, 1] and ``ior`` in :data:`IOR_RANGE` (F0
1.7–5.3 %), so a near-black fabric never becomes a grey mirror.  The upper end is
the isotropic (mean) index of textile fibres, 1.6, not the 1.8 the anisotropic
targets allow (birefringent polyester reaches 1.72 along the fibre only): the
fallback has no fuzz, sheen or anisotropy, so its fit pushes F0 to whatever bound it
is given to stand in for them (every reference in docs/exports.md ends at the
bound), and a preview must keep a dark fabric's normal-incidence reflectance
below 6 %.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.export.analytic_fit import FIBRE_IOR_RANGE, ParamSpec
from kesbrdf.export.microfacet import pair_geometry, schlick_weight

__all__ = ["PreviewSurface", "PREVIEW_SURFACE", "preview_surface_brdf", "normal_incidence_f0", "ROUGHNESS_MIN", "IOR_RANGE"]

#: roughness lower bound of the fit (α = 0.0025): a preview surface sharper than this is
#: a mirror, which no fabric is.
ROUGHNESS_MIN = 0.05
#: ``ior`` range of the fallback: textile fibres' lower end to their isotropic mean index
#: (module docstring); F0 = 1.7–5.3 %.
IOR_RANGE = (FIBRE_IOR_RANGE[0], 1.6)


def normal_incidence_f0(ior):
    """F0 = ((η − 1)/(η + 1))², the specular reflectance at normal incidence."""
    return ((np.asarray(ior, float) - 1.0) / (np.asarray(ior, float) + 1.0)) ** 2


def preview_surface_brdf(wi, wr, diffuse_color, roughness, ior, geo=None):
    """f_r (1/sr) of a UsdPreviewSurface with metallic 0 and no clearcoat, shape (N, C)."""
    g = geo if geo is not None else pair_geometry(wi, wr)
    diffuse_color = np.atleast_1d(np.asarray(diffuse_color, float))
    alpha = max(float(roughness), 1e-3) ** 2
    a2 = alpha * alpha
    nl = np.where(g.above, g.cos_i, 1.0)
    nv = np.where(g.above, g.cos_r, 1.0)
    D = a2 / (np.pi * (g.cos_h**2 * (a2 - 1.0) + 1.0) ** 2)
    k = 0.5 * alpha
    G = nl / (nl * (1 - k) + k) * nv / (nv * (1 - k) + k)
    f0 = normal_incidence_f0(ior)
    F = f0 + (1.0 - f0) * schlick_weight(np.maximum(g.cos_vh, 0.0))
    spec = F * G * D / (4.0 * nl * nv)
    f = (1.0 - F)[..., None] * diffuse_color / np.pi + spec[..., None]
    return np.where(g.above[..., None], f, 0.0)


class PreviewSurface:
    """UsdPreviewSurface: diffuse_color, roughness, ior (isotropic; no rotation)."""

    name = "preview_surface"
    rotation = None
    albedo_params = ("diffuse_color",)
    coupled_colors = ()

    def param_specs(self):
        return [
            ParamSpec("diffuse_color", 0.0, 1.0, 0.3, "color"),
            ParamSpec("roughness", ROUGHNESS_MIN, 1.0, 0.5),
            ParamSpec("ior", IOR_RANGE[0], IOR_RANGE[1], 1.5),
        ]

    def rotation_basins(self):
        return ((None, None, None),)

    def evaluate(self, p, wi, wr, geo=None):
        return preview_surface_brdf(wi, wr, p["diffuse_color"], p["roughness"], p["ior"], geo)

    def canonical(self, p):
        return dict(p)


PREVIEW_SURFACE = PreviewSurface()
