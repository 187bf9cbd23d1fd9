r"""Importance sampling of the measured lobe for the Mitsuba plugin.

The BSDF (see :mod:`kesbrdf.render.bsdf`) is a body term plus the KES lobe

.. math:: f_r = c + \frac{q(\phi, \gamma)}{\sqrt{\cos\theta_i\cos\theta_r}}

and is sampled with a two-component mixture, given the viewer direction ω_r
(Mitsuba's ``si.wi``):

* **lobe** (probability ``w``): a point (γ, φ) is drawn from the tabulated 2-D
  density ``p(γ, φ) ∝ q̄(φ, γ)·J(γ)`` (``mi.MarginalContinuous2D0``, bilinear and
  continuous, periodic in φ through a repeated first row), where q̄ is the channel
  mean of the tinted lobe and J the solid-angle Jacobian of the mapping, so that the
  solid-angle density of the light direction is close to proportional to q.
  The (γ, φ) point becomes a light direction ω_i:

  - ``deviation``: v = the point at angle γ from ω_r, azimuth α = φ + π in the frame
    (t₁, t₂) around ω_r, where t₁ is the warp axis x made orthogonal to ω_r; then
    ω_i = (−v.x, −v.y, v.z) (the mirror image, an isometry).  Near normal viewing α
    is exactly the deviation azimuth of the model; elsewhere it is close, and the
    pdf below is exact in any case.  J = sin γ.
  - ``halfvector``: the half vector h at polar angle γ/2 and azimuth φ (exact),
    ω_i = reflect(ω_r, h); p(ω_i) = p(h)/(4 ω_r·h).  J = sin(γ/2).

  Lobe samples beyond γ_max (the last measured deviation, where the table is held
  constant) are never drawn; the cosine component covers them.
* **cosine** (probability 1 − w): cosine-weighted hemisphere, for the body term.

The mixture pdf is ``w·p_lobe + (1 − w)·cos θ_i/π``; it is positive wherever
f_r cos θ_i is, so the estimator is unbiased.  ``w`` is the share of the lobe's
directional-albedo proxy ∫q dω in the total (lobe + π·c), clamped to
[:data:`MIN_LOBE_WEIGHT`, :data:`MAX_LOBE_WEIGHT`] so neither component vanishes.
"""

from __future__ import annotations

import math

import numpy as np

import drjit as dr
import mitsuba as mi

__all__ = ["LobeSampler", "lobe_density_table", "MIN_LOBE_WEIGHT", "MAX_LOBE_WEIGHT"]

#: Smallest / largest probability of the lobe component (keeps both techniques alive).
MIN_LOBE_WEIGHT = 0.1
MAX_LOBE_WEIGHT = 0.95
#: Below this sin γ the solid-angle density is evaluated at this value (γ → 0 is a
#: point of measure zero; the tabulated density vanishes there like sin γ does).
MIN_SIN_GAMMA = 1e-6


def lobe_density_table(q_mean: np.ndarray, gamma_grid: np.ndarray, mapping: str) -> np.ndarray:
    """Unnormalised sampling density on the (φ, γ) grid, shape (n_phi + 1, n_gamma).

    Parameters
    ----------
    q_mean : ndarray, shape (n_phi, n_gamma)
        Channel mean of the (tinted) lobe q, ≥ 0.
    gamma_grid : ndarray, shape (n_gamma,)
        Uniform γ nodes from 0 to γ_max, radians.
    mapping : {"deviation", "halfvector"}

    Returns
    -------
    ndarray, float32
        Rows are φ_j = j·2π/n_phi for j = 0..n_phi (row n_phi repeats row 0 so the
        bilinear density is periodic), columns are the γ nodes.
    """
    q = np.clip(np.nan_to_num(np.asarray(q_mean, float)), 0.0, None)
    jac = np.sin(gamma_grid) if mapping == "deviation" else np.sin(0.5 * gamma_grid)
    data = q * jac[None, :]
    data = np.concatenate([data, data[:1]], axis=0)
    if not np.any(data > 0):  # a lobe-free model: sample uniformly in (φ, γ)
        data = np.ones_like(data)
    return np.ascontiguousarray(data, dtype=np.float32)


def lobe_albedo_proxy(q_mean: np.ndarray, phi_grid: np.ndarray, gamma_grid: np.ndarray) -> float:
    """∫ q dω over the tabulated lobe (deviation sphere), a proxy of its albedo."""
    dphi = 2 * math.pi / phi_grid.size
    w = np.sin(gamma_grid) * np.gradient(gamma_grid)
    return float(np.sum(np.clip(q_mean, 0, None) * w[None, :]) * dphi)


class LobeSampler:
    """Mixture sampler (lobe + cosine) of one model; see the module docstring.

    Parameters
    ----------
    density : ndarray, shape (n_phi + 1, n_gamma)
        From :func:`lobe_density_table`.
    gamma_max : float
        Largest tabulated γ, radians.
    mapping : {"deviation", "halfvector"}
    lobe_weight : float
        Probability of the lobe component, [0, 1].
    """

    def __init__(self, density: np.ndarray, gamma_max: float, mapping: str, lobe_weight: float):
        self.mapping = mapping
        self.gamma_max = float(gamma_max)
        self.lobe_weight = float(lobe_weight)
        self.distr = mi.MarginalContinuous2D0(density, normalize=True)
        # density per unit square -> per (γ, φ) in radians
        self.scale = 1.0 / (self.gamma_max * 2.0 * math.pi)

    # -- frames -----------------------------------------------------------------
    @staticmethod
    def _frame(wr):
        """(t1, t2) ⟂ ω_r: the warp axis made orthogonal to ω_r (weft if degenerate)."""
        t1 = mi.Vector3f(1.0, 0.0, 0.0) - wr.x * wr
        n1 = dr.norm(t1)
        alt = mi.Vector3f(0.0, 1.0, 0.0) - wr.y * wr
        t1 = dr.select(n1 > 1e-5, t1, alt)
        t1 = dr.normalize(t1)
        t2 = dr.cross(wr, t1)
        return t1, t2

    # -- lobe ------------------------------------------------------------------
    def _sample_lobe(self, wr, u2):
        p, _ = self.distr.sample(u2)
        gamma = p.x * self.gamma_max
        phi = p.y * (2.0 * math.pi)
        if self.mapping == "deviation":
            t1, t2 = self._frame(wr)
            alpha = phi + math.pi
            sin_g, cos_g = dr.sincos(gamma)
            sin_a, cos_a = dr.sincos(alpha)
            v = cos_g * wr + sin_g * (cos_a * t1 + sin_a * t2)
            wi = mi.Vector3f(-v.x, -v.y, v.z)
        else:
            sin_t, cos_t = dr.sincos(0.5 * gamma)
            sin_p, cos_p = dr.sincos(phi)
            h = mi.Vector3f(sin_t * cos_p, sin_t * sin_p, cos_t)
            wi = 2.0 * dr.dot(wr, h) * h - wr
        return dr.normalize(wi)

    def _pdf_lobe(self, wr, wi):
        if self.mapping == "deviation":
            v = mi.Vector3f(-wi.x, -wi.y, wi.z)
            cos_g = dr.dot(v, wr)
            sin_g = dr.norm(dr.cross(v, wr))
            gamma = dr.atan2(sin_g, cos_g)
            t1, t2 = self._frame(wr)
            d = v - cos_g * wr
            alpha = dr.atan2(dr.dot(d, t2), dr.dot(d, t1))
            phi = alpha - math.pi
            jac = dr.maximum(sin_g, MIN_SIN_GAMMA)
            extra = 1.0
        else:
            h = dr.normalize(wi + wr)
            sin_t = dr.norm(mi.Vector2f(h.x, h.y))
            gamma = 2.0 * dr.atan2(sin_t, h.z)
            phi = dr.atan2(h.y, h.x)
            # p(γ, φ) dγ dφ -> p(θ_h, φ) = 2 p(γ, φ); solid angle of h: / sin θ_h;
            # reflection Jacobian: / (4 ω_r·h)
            jac = dr.maximum(sin_t, MIN_SIN_GAMMA)
            extra = 2.0 / dr.maximum(4.0 * dr.dot(wr, h), 1e-8)
        phi = phi - (2.0 * math.pi) * dr.floor(phi * (1.0 / (2.0 * math.pi)))
        x = gamma * (1.0 / self.gamma_max)
        y = phi * (1.0 / (2.0 * math.pi))
        inside = (x >= 0.0) & (x <= 1.0)
        dens = self.distr.eval(mi.Point2f(dr.clip(x, 0.0, 1.0), dr.clip(y, 0.0, 1.0)))
        return dr.select(inside, dens * self.scale * extra / jac, 0.0)

    # -- mixture ---------------------------------------------------------------
    def sample(self, wr, u1, u2):
        """Light direction ω_i for viewer ω_r (both fabric frame, upper hemisphere).

        Returns ``(wi, pdf, from_lobe)``; ``pdf`` is the mixture pdf (solid angle).
        """
        from_lobe = u1 < self.lobe_weight
        wi_cos = mi.warp.square_to_cosine_hemisphere(u2)
        if self.lobe_weight > 0.0:
            wi_lobe = self._sample_lobe(wr, u2)
            wi = dr.select(from_lobe, wi_lobe, wi_cos)
        else:
            wi = wi_cos
        return wi, self.pdf(wr, wi), from_lobe

    def pdf(self, wr, wi):
        """Mixture pdf (solid angle) of light direction ω_i given viewer ω_r."""
        p_cos = dr.maximum(wi.z, 0.0) * (1.0 / math.pi)
        if self.lobe_weight <= 0.0:
            return p_cos
        p_lobe = self._pdf_lobe(wr, wi)
        p = self.lobe_weight * p_lobe + (1.0 - self.lobe_weight) * p_cos
        return dr.select(wi.z > 0.0, p, 0.0)
