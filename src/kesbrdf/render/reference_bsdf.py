r"""Reference BRDFs rendered by Mitsuba 3 themselves (the ground truth of a comparison).

A KES model is fitted from 116 virtual measurements of a reference BRDF
(:func:`kesbrdf.measure.gonio.measure`).  To judge the model on a picture, the same scene is
rendered with the reference itself; this module makes each reference a Mitsuba BSDF.

* **Analytic references** (:class:`ReferenceBSDF`, plugin name ``kesbrdf_reference``):
  the reference's own equations in Dr.Jit, vectorised, single precision:

  - anisotropic Ward (:class:`kesbrdf.references.ward.AnisotropicWard`, Ward 1992 eq. 5);
  - Ashikhmin–Shirley (:class:`kesbrdf.references.ashikhmin_shirley.AshikhminShirley`,
    eqs. 1–5);
  - anisotropic GGX over a Lambertian body (:class:`kesbrdf.references.ggx.AnisotropicGGX`,
    Walter et al. 2007 eq. 20 with Heitz 2014 eqs. 85, 86, 99);
  - the Sadeghi et al. 2013 microcylinder cloth model
    (:class:`kesbrdf.references.sadeghi2013.Sadeghi2013`: Eqs. 2–15 as that module
    reads them, reciprocal or published form, the same tangent samples).  The sum over
    tangent samples is unrolled at trace time (one term per *distinct* tangent offset,
    weighted by how many arclength samples share it: identical offsets give identical
    terms, so this is the same sum).  Nothing is tabulated.

* **Measured RGL felts**: Mitsuba's own ``measured`` plugin (what
  :class:`kesbrdf.references.rgl.RGLMeasured` calls), wrapped in ``twosided`` when the
  scene asks for two-sided cloth.  It reads the tables with the camera in ``si.wi``,
  i.e. it equals ``RGLMeasured(path, parameterised_by="viewer")``.

Conventions (as :mod:`kesbrdf.render.bsdf`): the local x axis is the UV-u tangent =
the warp; Mitsuba's ``si.wi`` points to the camera (the references' ω_r) and ``wo`` to
the light (ω_i).  ``eval`` returns f_r·cos θ_i.

Sampling.  A two-component mixture, exactly as the ``kesbrdf`` plugin
(:mod:`kesbrdf.render.sampling`): the lobe component draws from the (φ, γ) table of the
KES model fitted from the reference's own paper-protocol measurement (a proposal only;
the pdf is exact, so the estimator is unbiased whatever the proposal), the rest is
cosine-weighted.  ``sampling="cosine"`` uses the cosine component alone.

Parameters (scene description) of ``kesbrdf_reference``
--------------------------------------------------------
reference : str
    A name of :data:`REFERENCE_NAMES` (not an RGL name: those are ``measured``).
params : str, optional
    JSON object of parameters overriding the named reference's defaults.
two_sided : bool
    Default ``False``.  When true, hits from the back are shaded as the front.
sampling : {"lobe", "cosine"}
"""

from __future__ import annotations

import json
import math

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf.errors import KesbrdfError
from kesbrdf.optics import fresnel_dielectric, schlick_weight
from kesbrdf.references.registry import RENDERABLE_REFERENCES, RGL_FILES, make_reference, rgl_path
from kesbrdf.render import sampling as _sampling
from kesbrdf.render.bsdf import FabricBSDF

__all__ = [
    "REFERENCE_NAMES",
    "RGL_FILES",
    "ReferenceBSDF",
    "make_reference",
    "reference_bsdf_dict",
    "reference_f_r",
    "register",
]

#: Every reference that can be rendered: :data:`kesbrdf.references.registry.REFERENCES` but the
#: Irawan–Marschner presets (numpy only, no Dr.Jit form here).
REFERENCE_NAMES = RENDERABLE_REFERENCES


# -----------------------------------------------------------------------------------
# Reference equations in Dr.Jit.  wi: light, wr: viewer, fabric frame, Vector3f.
# -----------------------------------------------------------------------------------


def _rgb(values) -> mi.Color3f:
    v = np.broadcast_to(np.ravel(np.asarray(values, float)), (3,)) if np.size(values) in (1, 3) else None
    if v is None:
        raise KesbrdfError(f"reference BSDF: expected 1 or 3 channels, got {np.size(values)}")
    return mi.Color3f(*[float(x) for x in v])


def _ward(ref):
    """Ward 1992 eq. 5 (see :mod:`kesbrdf.references.ward`)."""
    ax, ay = ref.alpha_x, ref.alpha_y
    rho_d = _rgb(ref.rho_d)
    rho_s = _rgb(ref.rho_s)
    norm = 1.0 / (4.0 * math.pi * ax * ay)

    def f(wi, wr):
        h = wi + wr
        expo = -(dr.square(h.x / ax) + dr.square(h.y / ay)) / dr.maximum(dr.square(h.z), 1e-30)
        spec = dr.exp(expo) * norm * dr.rsqrt(dr.maximum(wi.z * wr.z, 1e-30))
        return rho_d * (1.0 / math.pi) + rho_s * spec

    return f


def _ashikhmin_shirley(ref):
    """Ashikhmin–Shirley 2000 eqs. 1–5 (see :mod:`kesbrdf.references.ashikhmin_shirley`)."""
    n_u, n_v = ref.n_u, ref.n_v
    R_s = _rgb(ref.R_s)
    R_d = _rgb(ref.R_d)
    c_spec = math.sqrt((n_u + 1.0) * (n_v + 1.0)) / (8.0 * math.pi)
    c_diff = 28.0 / (23.0 * math.pi)

    def f(wi, wr):
        h = dr.normalize(wi + wr)
        hu2, hv2 = dr.square(h.x), dr.square(h.y)
        k_h = dr.dot(wi, h)
        s2 = hu2 + hv2
        expo = dr.select(s2 > 0.0, (n_u * hu2 + n_v * hv2) / dr.select(s2 > 0.0, s2, 1.0), n_u)
        lobe = dr.exp(expo * dr.log(dr.maximum(h.z, 1e-30)))
        spec = c_spec * lobe / (k_h * dr.maximum(wi.z, wr.z))
        fresnel = R_s + (1.0 - R_s) * schlick_weight(k_h, dr)
        shape = (1.0 - dr.power(1.0 - 0.5 * wi.z, 5.0)) * (1.0 - dr.power(1.0 - 0.5 * wr.z, 5.0))
        return spec * fresnel + c_diff * R_d * (1.0 - R_s) * shape

    return f


def _ggx(ref):
    """Anisotropic GGX + Lambertian body (see :mod:`kesbrdf.references.ggx`)."""
    ax, ay, eta = ref.alpha_x, ref.alpha_y, ref.eta
    rho_d = _rgb(ref.rho_d)
    k_s = _rgb(ref.k_s)

    def lam(w):
        return 0.5 * (dr.sqrt(1.0 + (dr.square(ax * w.x) + dr.square(ay * w.y)) / dr.maximum(dr.square(w.z), 1e-30))
                      - 1.0)

    def f(wi, wr):
        h = dr.normalize(wi + wr)
        q = dr.square(h.x / ax) + dr.square(h.y / ay) + dr.square(h.z)
        d = 1.0 / (math.pi * ax * ay * dr.square(q))
        g2 = 1.0 / (1.0 + lam(wi) + lam(wr))
        fres = fresnel_dielectric(dr.dot(wi, h), eta, dr)
        spec = fres * d * g2 / (4.0 * dr.maximum(wi.z * wr.z, 1e-30))
        body = (1.0 - fresnel_dielectric(wi.z, eta, dr)) * (1.0 - fresnel_dielectric(wr.z, eta, dr))
        return k_s * spec + rho_d * (body / math.pi)

    return f


def _gaussian(g, x):
    return dr.exp(x * x * (-1.0 / (2.0 * g * g))) * (1.0 / (math.sqrt(2.0 * math.pi) * g))


def _correlated(cos_i, cos_r, u):
    m_i = dr.maximum(cos_i, 0.0)
    m_r = dr.maximum(cos_r, 0.0)
    return (1.0 - u) * m_i * m_r + u * dr.minimum(m_i, m_r)


def _polar(x, y):
    r = dr.sqrt(x * x + y * y)
    pos = r > 0.0
    safe = dr.select(pos, r, 1.0)
    return r, dr.select(pos, x / safe, 1.0), dr.select(pos, y / safe, 0.0)


def _family_axes(w, j):
    if j == 0:
        return w.x, -w.y, w.z
    return w.y, w.x, w.z


def _sadeghi(ref):
    """Sadeghi et al. 2013 as :class:`~kesbrdf.references.sadeghi2013.Sadeghi2013` evaluates it."""
    fabric = ref.fabric
    sigma_u = ref.sigma_u
    inv_two_sigma2 = 1.0 / (2.0 * sigma_u * sigma_u)
    gap = 1.0 - fabric.warp.a - fabric.weft.a
    A = [_rgb(fam.A) for fam in fabric.families]
    # distinct tangent offsets with their multiplicity (same sum, fewer traced terms)
    groups = []
    for family, alphas in zip(fabric.families, ref.alphas):
        if alphas.size == 0 or family.a == 0.0:
            groups.append(None)
            continue
        values, counts = np.unique(np.asarray(alphas, float), return_counts=True)
        groups.append((values, counts * (family.a / alphas.size)))
    reciprocal = ref.reciprocal

    def f(wi, wr):
        zero = dr.zeros(mi.Float, dr.width(wi.x))
        surf_i, surf_r = mi.Float(zero), mi.Float(zero)
        vol_i, vol_r = [mi.Float(zero), mi.Float(zero)], [mi.Float(zero), mi.Float(zero)]
        q_r = gap * wr.z
        q_i = gap * wi.z
        for j, family in enumerate(fabric.families):
            if groups[j] is None:
                continue
            along_i, across_i, z_i = _family_axes(wi, j)
            along_r, across_r, z_r = _family_axes(wr, j)
            inv_r_i = 1.0 / dr.maximum(dr.sqrt(along_i * along_i + z_i * z_i), 1e-30)
            inv_r_r = 1.0 / dr.maximum(dr.sqrt(along_r * along_r + z_r * z_r), 1e-30)
            psi_d = dr.atan2(along_i, z_i) - dr.atan2(along_r, z_r)
            psi_d = psi_d + math.pi
            psi_d = psi_d - (2.0 * math.pi) * dr.floor(psi_d * (1.0 / (2.0 * math.pi))) - math.pi
            u_psi = dr.exp(-psi_d * psi_d * inv_two_sigma2)
            eta, kd = family.eta, family.kd
            for alpha, weight in zip(*groups[j]):
                cos_a, sin_a = math.cos(alpha), math.sin(alpha)
                t_i = cos_a * along_i + sin_a * z_i
                n_i = cos_a * z_i - sin_a * along_i
                t_r = cos_a * along_r + sin_a * z_r
                n_r = cos_a * z_r - sin_a * along_r
                cos_theta_i, cos_phi_i, sin_phi_i = _polar(n_i, across_i)
                cos_theta_r, cos_phi_r, sin_phi_r = _polar(n_r, across_r)
                theta_h = 0.5 * (dr.atan2(t_i, cos_theta_i) + dr.atan2(t_r, cos_theta_r))
                cos_theta_diff = dr.clip(cos_theta_i * cos_theta_r + t_i * t_r, -1.0, 1.0)
                cos_theta_d = dr.maximum(dr.sqrt(0.5 * (1.0 + cos_theta_diff)), 1e-4)
                cos_phi_d = dr.clip(cos_phi_i * cos_phi_r + sin_phi_i * sin_phi_r, -1.0, 1.0)
                phi_d = dr.acos(cos_phi_d)
                cos_half_phi_d = dr.sqrt(0.5 * (1.0 + cos_phi_d))
                F_r = fresnel_dielectric(cos_theta_d * cos_half_phi_d, eta, dr)
                surf = F_r * cos_half_phi_d * _gaussian(family.gamma_s, theta_h)
                F_t = 1.0 - F_r
                vol = (
                    F_t * F_t
                    * ((1.0 - kd) * _gaussian(family.gamma_v, theta_h) + kd)
                    / dr.maximum(cos_theta_i + cos_theta_r, 1e-6)
                )
                cos_psi_i = n_i * inv_r_i
                cos_psi_r = n_r * inv_r_r
                u_phi = dr.exp(-phi_d * phi_d * inv_two_sigma2)
                mp = (
                    _correlated(cos_phi_i, cos_phi_r, u_phi)
                    * _correlated(cos_psi_i, cos_psi_r, u_psi)
                    / (cos_theta_d * cos_theta_d)
                )
                w = float(weight)
                surf_i += w * surf * mp * cos_theta_i
                vol_i[j] += w * vol * mp * cos_theta_i
                q_r += w * dr.maximum(cos_psi_r, 0.0)
                if reciprocal:
                    surf_r += w * surf * mp * cos_theta_r
                    vol_r[j] += w * vol * mp * cos_theta_r
                    q_i += w * dr.maximum(cos_psi_i, 0.0)
        num_i = surf_i + vol_i[0] * A[0] + vol_i[1] * A[1]
        out = dr.select(q_r > 0.0, num_i / (q_r * wi.z), 0.0)
        if reciprocal:
            num_r = surf_r + vol_r[0] * A[0] + vol_r[1] * A[1]
            out = 0.5 * (out + dr.select(q_i > 0.0, num_r / (q_i * wr.z), 0.0))
        return out

    return f


def reference_f_r(ref):
    """Dr.Jit ``f(wi, wr) -> Color3f`` (1/sr, no cosine, upper hemisphere) of a numpy reference."""
    from kesbrdf.references.ashikhmin_shirley import AshikhminShirley
    from kesbrdf.references.ggx import AnisotropicGGX
    from kesbrdf.references.sadeghi2013 import Sadeghi2013
    from kesbrdf.references.ward import AnisotropicWard

    if isinstance(ref, AnisotropicWard):
        return _ward(ref)
    if isinstance(ref, AshikhminShirley):
        return _ashikhmin_shirley(ref)
    if isinstance(ref, AnisotropicGGX):
        return _ggx(ref)
    if isinstance(ref, Sadeghi2013):
        return _sadeghi(ref)
    raise KesbrdfError(
        f"reference BSDF: expected a Ward, Ashikhmin-Shirley, GGX or Sadeghi2013 reference, got {type(ref).__name__}"
    )


# -----------------------------------------------------------------------------------
# The plugin
# -----------------------------------------------------------------------------------


def _prop(props, name, default=None):
    return props[name] if name in props else default


def proposal_model(ref):
    """KES model fitted from the reference's paper-protocol measurement (the sampling proposal)."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    return fit(measure(ref, protocol="paper"), fallback="log")


class ReferenceBSDF(FabricBSDF):
    """Mitsuba BSDF evaluating an analytic reference BRDF (module docstring)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        name = str(_prop(props, "reference", ""))
        if name in RGL_FILES:
            raise KesbrdfError(f"reference {name!r} is measured: render it with reference_bsdf_dict (Mitsuba's 'measured')")
        params = _prop(props, "params")
        self.name = name
        self.ref = make_reference(name, str(params) if params is not None else None)
        self._f = reference_f_r(self.ref)
        self.two_sided = bool(_prop(props, "two_sided", False))
        sampling = str(_prop(props, "sampling", "lobe"))
        if sampling not in _SAMPLINGS:
            raise KesbrdfError(f"kesbrdf_reference: unknown sampling {sampling!r}; expected one of {', '.join(_SAMPLINGS)}")
        self.sampling = sampling
        self.sampler = _make_sampler(self.ref, sampling)
        self._set_flags()

    def f_r(self, wi, wr, active=True):
        """f_r (1/sr) for light ω_i and viewer ω_r (fabric frame); 0 below the horizon."""
        above = (wi.z > 0.0) & (wr.z > 0.0) & active
        return dr.select(above, self._f(wi, wr), 0.0)

    def to_string(self):
        return f"ReferenceBSDF[reference={self.name!r}, two_sided={self.two_sided}, sampling={self.sampling!r}]"


_SAMPLINGS = ("lobe", "cosine")
#: Proposal samplers by (reference repr, sampling), built once per process.
_SAMPLER_CACHE: dict = {}


def _make_sampler(ref, sampling: str) -> _sampling.LobeSampler:
    key = (repr(getattr(ref, "params", lambda: ref)()), sampling)
    if key in _SAMPLER_CACHE:
        return _SAMPLER_CACHE[key]
    model = proposal_model(ref)
    table = model.table if model.table.shape[-1] == 3 else np.repeat(model.table, 3, axis=-1)
    q_mean = np.clip(np.nan_to_num(table), 0.0, None).mean(axis=-1)
    if sampling == "cosine":
        weight = 0.0
    else:
        lobe = _sampling.lobe_albedo_proxy(q_mean, model.phi_grid, model.gamma_grid)
        diffuse = math.pi * float(np.mean(model.body))
        weight = _sampling.lobe_weight(lobe, diffuse)
    sampler = _sampling.LobeSampler(
        _sampling.lobe_density_table(q_mean, model.gamma_grid, "deviation"),
        float(model.gamma_grid[-1]),
        "deviation",
        weight,
    )
    _SAMPLER_CACHE[key] = sampler
    return sampler


def reference_bsdf_dict(name: str, two_sided: bool = True, params=None, sampling: str = "lobe") -> dict:
    """Mitsuba BSDF dict rendering the reference ``name`` itself (scene ``cloth_bsdf``)."""
    if name not in REFERENCE_NAMES:
        raise KesbrdfError(f"unknown reference {name!r}; expected one of {', '.join(REFERENCE_NAMES)}")
    if name in RGL_FILES:
        d = {"type": "measured", "filename": str(rgl_path(name))}
        return {"type": "twosided", "bsdf": d} if two_sided else d
    d = {"type": "kesbrdf_reference", "reference": name, "two_sided": bool(two_sided), "sampling": sampling}
    if params:
        d["params"] = params if isinstance(params, str) else json.dumps(params)
    return d


def register() -> None:
    """Register the plugin under the name ``kesbrdf_reference`` (idempotent)."""
    mi.register_bsdf("kesbrdf_reference", lambda props: ReferenceBSDF(props))
