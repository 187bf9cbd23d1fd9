r"""Microfacet and sheen lobes shared by the analytic material models (numpy).

Every function broadcasts over leading axes; direction vectors carry their components
on the last axis and are expressed in a shading frame whose z axis is the normal.
The formulas and their sources:

- :func:`ggx_anisotropic_ndf` — Burley's anisotropic GGX (Trowbridge–Reitz) NDF, as
  written normatively in ``KHR_materials_anisotropy``:
  :math:`D(h) = 1 / (\pi\alpha_t\alpha_b((h\cdot t)^2/\alpha_t^2 + (h\cdot b)^2/\alpha_b^2 + (h\cdot n)^2)^2)`.
- :func:`ggx_anisotropic_visibility` — the height-correlated Smith visibility
  :math:`V = G_2 / (4|n\cdot l||n\cdot v|) = 0.5 / (n\cdot l\,|(\alpha_t t\cdot v, \alpha_b b\cdot v, n\cdot v)| + n\cdot v\,|(\alpha_t t\cdot l, \alpha_b b\cdot l, n\cdot l)|)`
  (glTF sample implementation of the anisotropy extension; Heitz 2014 eq. 99).
- :func:`charlie_ndf`, :func:`charlie_visibility` — the Imageworks "Charlie" sheen
  (Conty & Kulla 2017) exactly as ``KHR_materials_sheen`` writes it, with
  :func:`charlie_albedo` (the directional albedo E(μ, r) of that lobe, which the sheen
  extension tells implementations to tabulate) integrated here by quadrature.
- :func:`fresnel_dielectric`, :func:`schlick_weight` — the unpolarised Fresnel reflectance of
  a dielectric and Schlick's weight, from :mod:`kesbrdf.optics` (re-exported here).
- :func:`imageworks_sheen` and :func:`zeltner_sheen` — the two ``sheen_bsdf`` modes of
  the MaterialX 1.39 reference implementation (``mx_microfacet_sheen.glsl``), which
  Standard Surface (``sheen``) and OpenPBR (``fuzz``) use; their directional albedos are
  MaterialX's closed-form fits.
- :func:`ggx_directional_albedo` — MaterialX's rational fit of the GGX directional albedo
  (``mx_ggx_dir_albedo_analytic``), used for the layer throughput 1 − E.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from kesbrdf.optics import fresnel_dielectric, schlick_weight

__all__ = [
    "PairGeometry",
    "pair_geometry",
    "half_vector",
    "ggx_anisotropic_ndf",
    "ggx_anisotropic_visibility",
    "schlick_weight",
    "fresnel_dielectric",
    "charlie_ndf",
    "charlie_visibility",
    "charlie_lambda",
    "charlie_albedo",
    "imageworks_sheen",
    "imageworks_sheen_albedo",
    "zeltner_sheen",
    "zeltner_sheen_albedo",
    "ggx_directional_albedo",
    "tangent_frame",
    "ALPHA_MIN",
]

#: α below this is clamped: D is a delta at α = 0 and no fit needs it sharper.
ALPHA_MIN = 1e-4


def half_vector(wi, wr):
    """Unit half vector h = (wi + wr)/|wi + wr| (zero length gives the normal)."""
    h = np.asarray(wi, float) + np.asarray(wr, float)
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    return np.where(norm > 1e-12, h / np.where(norm > 1e-12, norm, 1.0), np.array([0.0, 0.0, 1.0]))


@dataclasses.dataclass(frozen=True)
class PairGeometry:
    """What every lobe needs of a set of (wi, wr) pairs, computed once per fit.

    ``h`` is the unit half vector, ``cos_i``, ``cos_r``, ``cos_h`` its angles to the
    normal (z) and ``cos_vh`` = wr·h; ``above`` marks pairs with both directions above
    the horizon.  Shapes (N, 3) and (N,).  ``mu_i`` / ``mu_r`` are the distinct values
    of ``cos_i`` / ``cos_r`` (a fit grid has a few bands), ``mu_i_index`` / ``mu_r_index``
    map the pairs onto them: :meth:`on_cos_i` evaluates a function of cos θ_i once per band.
    """

    wi: np.ndarray
    wr: np.ndarray
    h: np.ndarray
    cos_i: np.ndarray
    cos_r: np.ndarray
    cos_h: np.ndarray
    cos_vh: np.ndarray
    above: np.ndarray
    mu_i: np.ndarray
    mu_i_index: np.ndarray
    mu_r: np.ndarray
    mu_r_index: np.ndarray

    def on_cos_i(self, func):
        """``func(cos θ_i)`` per pair, evaluated on the distinct values only."""
        return np.asarray(func(self.mu_i))[self.mu_i_index]

    def on_cos_r(self, func):
        """``func(cos θ_r)`` per pair, evaluated on the distinct values only."""
        return np.asarray(func(self.mu_r))[self.mu_r_index]


def pair_geometry(wi, wr) -> PairGeometry:
    """:class:`PairGeometry` of direction pairs ``wi``, ``wr`` (N, 3)."""
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    h = half_vector(wi, wr)
    mu_i, mu_i_index = np.unique(wi[..., 2], return_inverse=True)
    mu_r, mu_r_index = np.unique(wr[..., 2], return_inverse=True)
    return PairGeometry(
        wi=wi, wr=wr, h=h, cos_i=wi[..., 2], cos_r=wr[..., 2], cos_h=h[..., 2],
        cos_vh=np.sum(wr * h, axis=-1), above=(wi[..., 2] > 0) & (wr[..., 2] > 0),
        mu_i=mu_i, mu_i_index=mu_i_index.reshape(wi.shape[:-1]), mu_r=mu_r, mu_r_index=mu_r_index.reshape(wr.shape[:-1]),
    )


def tangent_frame(rotation):
    """Tangent t = (cos ρ, sin ρ, 0) and bitangent b = n × t for a rotation ρ about z."""
    c, s = np.cos(rotation), np.sin(rotation)
    return np.array([c, s, 0.0]), np.array([-s, c, 0.0])


def ggx_anisotropic_ndf(h, t, b, alpha_t, alpha_b):
    """Anisotropic GGX NDF D(h) (``KHR_materials_anisotropy``, normative), 1/sr."""
    alpha_t = np.maximum(alpha_t, ALPHA_MIN)
    alpha_b = np.maximum(alpha_b, ALPHA_MIN)
    ht = h @ t
    hb = h @ b
    hn = h[..., 2]
    denom = (ht / alpha_t) ** 2 + (hb / alpha_b) ** 2 + hn**2
    return np.where(hn > 0, 1.0 / (np.pi * alpha_t * alpha_b * denom**2), 0.0)


def ggx_anisotropic_visibility(wi, wr, t, b, alpha_t, alpha_b):
    """Height-correlated Smith visibility V = G₂/(4 n·l n·v) of anisotropic GGX."""
    alpha_t = np.maximum(alpha_t, ALPHA_MIN)
    alpha_b = np.maximum(alpha_b, ALPHA_MIN)
    nl = wi[..., 2]
    nv = wr[..., 2]
    lam_v = np.sqrt((alpha_t * (wr @ t)) ** 2 + (alpha_b * (wr @ b)) ** 2 + nv**2)
    lam_l = np.sqrt((alpha_t * (wi @ t)) ** 2 + (alpha_b * (wi @ b)) ** 2 + nl**2)
    return 0.5 / (nl * lam_v + nv * lam_l)


# ------------------------------------------------------------------ Charlie (glTF sheen)
def charlie_ndf(cos_theta_h, r):
    """Charlie sheen NDF (2 + 1/r) sin^{1/r}θ_h / 2π, r = sheenRoughness² (KHR_materials_sheen)."""
    sin2 = np.clip(1.0 - cos_theta_h**2, 0.0, 1.0)
    inv_r = 1.0 / r
    return (2.0 + inv_r) * sin2 ** (0.5 * inv_r) / (2.0 * np.pi)


def _charlie_l(x, r):
    w = (1.0 - r) ** 2
    a = 21.5473 * (1 - w) + 25.3245 * w
    b = 3.82987 * (1 - w) + 3.32435 * w
    c = 0.19823 * (1 - w) + 0.16801 * w
    d = -1.97760 * (1 - w) + -1.27393 * w
    e = -4.32054 * (1 - w) + -4.85967 * w
    return a / (1.0 + b * np.power(x, c)) + d * x + e


def charlie_lambda(cos_theta, r):
    """Λ(cos θ) of the Charlie sheen visibility (KHR_materials_sheen's fitted curve)."""
    x = np.abs(cos_theta)
    return np.where(x < 0.5, np.exp(_charlie_l(x, r)), np.exp(2.0 * _charlie_l(0.5, r) - _charlie_l(1.0 - x, r)))


def charlie_visibility(cos_i, cos_r, r):
    """Charlie sheen visibility 1/((1 + Λ(n·v) + Λ(n·l))·4 n·v n·l) (KHR_materials_sheen)."""
    return 1.0 / ((1.0 + charlie_lambda(cos_r, r) + charlie_lambda(cos_i, r)) * (4.0 * cos_r * cos_i))


#: Node grids of the Charlie albedo table E(μ, sheenRoughness).
CHARLIE_MU_NODES = np.linspace(0.0, 1.0, 33)
CHARLIE_ROUGHNESS_NODES = np.linspace(0.05, 1.0, 20)


@functools.lru_cache(maxsize=1)
def _charlie_albedo_table() -> np.ndarray:
    """E(μ_v, sheenRoughness) = ∫ D_c V_c cos θ_l dω_l by Gauss–Legendre × midpoint quadrature."""
    x, w = np.polynomial.legendre.leggauss(96)
    mu_l = 0.5 * (x + 1.0)
    w_mu = 0.5 * w
    n_phi = 96
    phi = (np.arange(n_phi) + 0.5) * (np.pi / n_phi)  # symmetric about the plane of v
    w_phi = 2.0 * np.pi / n_phi
    mu_v = np.clip(CHARLIE_MU_NODES, 1e-3, 1.0)
    sr = CHARLIE_ROUGHNESS_NODES
    r = (sr**2)[:, None, None, None]
    sin_l = np.sqrt(1 - mu_l**2)
    l = np.stack(np.broadcast_arrays(sin_l[:, None] * np.cos(phi), sin_l[:, None] * np.sin(phi), mu_l[:, None]), -1)
    v = np.stack([np.sqrt(1 - mu_v**2), np.zeros_like(mu_v), mu_v], -1)
    h = half_vector(l[None], v[:, None, None])  # (μv, μl, φ, 3)
    f = charlie_ndf(h[..., 2][None], r) * charlie_visibility(mu_l[None, None, :, None], mu_v[None, :, None, None], r)
    E = np.einsum("rvlp,l->rv", f * mu_l[None, None, :, None], w_mu) * w_phi
    return np.clip(E.T, 0.0, 1.0)  # (μ, roughness); Charlie is not energy-conserving at grazing


def charlie_albedo(cos_theta, sheen_roughness):
    """Directional albedo E(μ, sheenRoughness) of the Charlie lobe (bilinear in a table)."""
    E = _charlie_albedo_table()
    mu = np.clip(np.abs(cos_theta), 0.0, 1.0) * (CHARLIE_MU_NODES.size - 1)
    sr = np.clip(sheen_roughness, CHARLIE_ROUGHNESS_NODES[0], 1.0)
    u = (sr - CHARLIE_ROUGHNESS_NODES[0]) / (CHARLIE_ROUGHNESS_NODES[1] - CHARLIE_ROUGHNESS_NODES[0])
    i = np.minimum(np.floor(mu).astype(int), CHARLIE_MU_NODES.size - 2)
    j = np.minimum(np.floor(u).astype(int), CHARLIE_ROUGHNESS_NODES.size - 2)
    fi = mu - i
    fj = u - j
    return (E[i, j] * (1 - fi) + E[i + 1, j] * fi) * (1 - fj) + (E[i, j + 1] * (1 - fi) + E[i + 1, j + 1] * fi) * fj


# --------------------------------------------------------------- MaterialX sheen_bsdf
def imageworks_sheen(cos_i, cos_r, cos_h, roughness):
    """MaterialX ``sheen_bsdf`` mode "conty_kulla": D_c / (4 (n·l + n·v − n·l n·v)), 1/sr."""
    inv = 1.0 / np.maximum(roughness, 0.005)
    sin2 = np.clip(1.0 - cos_h**2, 0.0, 1.0)
    D = (2.0 + inv) * sin2 ** (0.5 * inv) / (2.0 * np.pi)
    return D / (4.0 * (cos_i + cos_r - cos_i * cos_r))


def imageworks_sheen_albedo(cos_r, roughness):
    """MaterialX rational fit of the Imageworks sheen albedo (``..._dir_albedo_analytic``)."""
    x = cos_r
    y = roughness
    rx = 13.67300 - 68.78018 * x + 799.08825 * y - 905.00061 * x * y + 60.28956 * x**2 + 1086.96473 * y**2
    ry = 1.0 + 61.57746 * x + 442.78211 * y + 2597.49308 * x * y + 121.81241 * x**2 + 3045.55075 * y**2
    return np.clip(rx / ry, 0.0, 1.0)


def zeltner_sheen_albedo(cos_r, roughness):
    """MaterialX Gaussian fit of the Zeltner et al. 2022 LTC sheen albedo."""
    x = cos_r
    y = np.clip(roughness, 0.01, 1.0)
    s = y * (0.0206607 + 1.58491 * y) / (0.0379424 + y * (1.32227 + y))
    m = y * (-0.193854 + y * (-1.14885 + y * (1.7932 - 0.95943 * y * y))) / (0.046391 + y)
    o = y * (0.000654023 + (-0.0207818 + 0.119681 * y) * y) / (1.26264 + y * (-1.92021 + y))
    return np.clip(np.exp(-0.5 * ((x - m) / s) ** 2) / (s * np.sqrt(2.0 * np.pi)) + o, 0.0, 1.0)


def zeltner_sheen(wi, wr, roughness):
    """f_r of MaterialX ``sheen_bsdf`` mode "zeltner" with unit colour and weight, 1/sr.

    The LTC distribution D_ltc(l) (a density over l) times the albedo E(μ_v, r), divided
    by cos θ_l so that it is a BRDF: f = E · D_ltc / (n·l).
    """
    y = np.clip(roughness, 0.01, 1.0)
    nv = np.clip(wr[..., 2], 1e-6, 1.0)
    a_inv = (2.58126 * nv + 0.813703 * y) * y / (1.0 + 0.310327 * nv * nv + 2.60994 * nv * y)
    b_inv = np.sqrt(1.0 - nv) * (y - 1.0) * y**3 / (0.0000254053 + 1.71228 * nv - 1.71506 * nv * y + 1.34174 * y * y)
    # LTC frame: X in the plane of v and n, Y = n × X (at v = n any azimuth will do)
    xv = wr[..., :2]
    len_x = np.linalg.norm(xv, axis=-1)
    safe = len_x > 1e-9
    X0 = np.where(safe, xv[..., 0] / np.where(safe, len_x, 1.0), 1.0)
    X1 = np.where(safe, xv[..., 1] / np.where(safe, len_x, 1.0), 0.0)
    wx = wi[..., 0] * X0 + wi[..., 1] * X1
    wy = -wi[..., 0] * X1 + wi[..., 1] * X0
    wz = wi[..., 2]
    ox = a_inv * wx + b_inv * wz
    oy = a_inv * wy
    len2 = ox**2 + oy**2 + wz**2
    # D_ltc(w) = D_o(M⁻¹w/|M⁻¹w|)·|M⁻¹|/|M⁻¹w|³ = (w_z/π)·(a_inv/|M⁻¹w|²)², and f = E·D_ltc/w_z
    return np.where(wz > 0, zeltner_sheen_albedo(nv, y) / np.pi * (a_inv / len2) ** 2, 0.0)


def ggx_directional_albedo(cos_r, alpha, F0, F90):
    """MaterialX rational fit of the GGX directional albedo E = F0·A + F90·B."""
    x = cos_r
    y = alpha
    x2, y2 = x * x, y * y
    c = np.array(
        [
            [0.1003, 0.9345, 1.0, 1.0],
            [-0.6303, -2.323, -1.765, 0.2281],
            [9.748, 2.229, 8.263, 15.94],
            [-2.038, -3.748, 11.53, -55.83],
            [29.34, 1.424, 28.96, 13.08],
            [-8.245, -0.7684, -7.507, 41.26],
            [-26.44, 1.436, -36.11, 54.9],
            [19.99, 0.2913, 15.86, 300.2],
            [-5.448, 0.6286, 33.37, -285.1],
        ]
    )
    terms = np.stack(np.broadcast_arrays(np.ones_like(x * y), x, y, x * y, x2, y2, x2 * y, x * y2, x2 * y2), -1)
    r = terms @ c
    A = np.clip(r[..., 0] / r[..., 2], 0.0, 1.0)
    B = np.clip(r[..., 1] / r[..., 3], 0.0, 1.0)
    return F0 * A[..., None] + F90 * B[..., None]
