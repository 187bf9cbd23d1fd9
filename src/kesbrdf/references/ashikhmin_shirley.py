"""Anisotropic Phong BRDF of Ashikhmin and Shirley (2000).

M. Ashikhmin, P. Shirley, "An Anisotropic Phong BRDF Model", journal of graphics
tools 5(2):25–32, 2000.

The BRDF is a specular lobe plus the paper's coupled, non-Lambertian diffuse term:

.. math:: \\rho(k_1, k_2) = \\rho_s(k_1, k_2) + \\rho_d(k_1, k_2)

Here k_1 = ω_i points toward the light and k_2 = ω_r toward the viewer.

* **Specular.** Its half-vector exponent is n_u along the tangent u = x (warp) and n_v
  along v = y (weft). It is weighted by Schlick's Fresnel approximation with normal
  reflectance R_s.
* **Diffuse.** Its weight (1 − R_s) and its two Schlick-like factors make the sum
  conserve energy for R_s + R_d ≤ 1 (the paper's aim; this module's tests check it by
  quadrature).

The model is reciprocal by construction. The equations are numbered in the paper's
order: (1) the sum, (2) the specular term in (φ_h) form, (3) Schlick's Fresnel, (4) the
Cartesian form of the specular exponent, and (5) the diffuse term. The printed numbering
could not be checked here; the formulas are the standard ones.

Conventions: fabric frame x = warp, y = weft, z = normal; ``wi`` toward the light, ``wr``
toward the viewer; f_r in 1/sr. A pair with either direction at or below the horizon
gives 0, and a NaN in either direction gives NaN.

>>> import numpy as np
>>> brdf = AshikhminShirley(n_u=10.0, n_v=100.0, R_s=0.05, R_d=0.5)
>>> brdf.channels
('value',)
>>> brdf([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]).round(5).tolist()
[0.23905]
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import KesbrdfError
from kesbrdf.optics import schlick_weight
from kesbrdf.references.base import ReferenceBRDF, default_channels

__all__ = ["AshikhminShirley"]


class AshikhminShirleyError(KesbrdfError):
    """Invalid parameters for the Ashikhmin–Shirley BRDF."""


class AshikhminShirley(ReferenceBRDF):
    """Ashikhmin–Shirley anisotropic Phong BRDF, callable as ``f(wi, wr) -> (..., C)``.

    .. math::
        \\rho_s = \\frac{\\sqrt{(n_u+1)(n_v+1)}}{8\\pi}
                 \\frac{(n\\cdot h)^{\\frac{n_u (h\\cdot u)^2 + n_v (h\\cdot v)^2}
                                           {1 - (h\\cdot n)^2}}}
                       {(h\\cdot k)\\,\\max(n\\cdot k_1,\\ n\\cdot k_2)}\\,F(h\\cdot k)
        \\qquad (2, 4)

        F(h\\cdot k) = R_s + (1 - R_s)(1 - h\\cdot k)^5 \\qquad (3)

        \\rho_d = \\frac{28 R_d}{23\\pi}(1 - R_s)
                 \\Big(1 - \\big(1 - \\tfrac{n\\cdot k_1}{2}\\big)^5\\Big)
                 \\Big(1 - \\big(1 - \\tfrac{n\\cdot k_2}{2}\\big)^5\\Big) \\qquad (5)

    Here h = (k_1 + k_2)/|k_1 + k_2|, u = x (warp), v = y (weft) and n = z.

    Parameters
    ----------
    n_u, n_v : float
        Phong exponents of the half vector along x (warp) and y (weft), ≥ 0. A larger
        exponent gives a narrower lobe in that direction.
    R_s : float or array_like, shape (C,)
        Specular reflectance at normal incidence, per channel, in [0, 1].
    R_d : float or array_like, shape (C,)
        Diffuse reflectance, per channel, in [0, 1]. R_s and R_d broadcast to C
        channels. R_s + R_d ≤ 1 keeps the BRDF energy conserving.
    channels : sequence of str, optional
        Channel names. Default: ``("value",)`` for one channel, ``("R", "G", "B")`` for
        three, otherwise ``("c0", "c1", ...)``.
    """

    error = AshikhminShirleyError

    def __init__(self, n_u: float, n_v: float, R_s=0.05, R_d=0.5, channels=None) -> None:
        for name, value in (("n_u", n_u), ("n_v", n_v)):
            if not (np.isscalar(value) and np.isfinite(value) and value >= 0):
                raise AshikhminShirleyError(
                    f"AshikhminShirley {name}: expected a finite exponent >= 0, got {value!r}"
                )
        R_s = np.atleast_1d(np.asarray(R_s, dtype=float))
        R_d = np.atleast_1d(np.asarray(R_d, dtype=float))
        if R_s.ndim != 1 or R_d.ndim != 1:
            raise AshikhminShirleyError(
                f"AshikhminShirley R_s, R_d: expected scalars or 1-D per-channel arrays, "
                f"got shapes {R_s.shape} and {R_d.shape}"
            )
        try:
            R_s, R_d = np.broadcast_arrays(R_s, R_d)
        except ValueError:
            raise AshikhminShirleyError(
                f"AshikhminShirley R_s, R_d: expected the same number of channels, got "
                f"{R_s.size} and {R_d.size}"
            ) from None
        for name, value in (("R_s", R_s), ("R_d", R_d)):
            if not np.all((value >= 0) & (value <= 1)):
                raise AshikhminShirleyError(
                    f"AshikhminShirley {name}: expected values in [0, 1], got {value.tolist()}"
                )
        self.n_u = float(n_u)
        self.n_v = float(n_v)
        self.R_s = R_s.copy()
        self.R_d = R_d.copy()
        if channels is None:
            channels = default_channels(self.R_s.size)
        channels = tuple(str(c) for c in channels)
        if len(channels) != self.R_s.size:
            raise AshikhminShirleyError(
                f"AshikhminShirley channels: expected {self.R_s.size} names, got {len(channels)}"
            )
        self.channels = channels

    def params(self) -> dict:
        """JSON-ready description of this reference (recorded by the virtual gonioreflectometer)."""
        return {
            "reference": "ashikhmin_shirley",
            "n_u": self.n_u,
            "n_v": self.n_v,
            "R_s": self.R_s.tolist(),
            "R_d": self.R_d.tolist(),
        }

    def __repr__(self) -> str:
        return (
            f"AshikhminShirley(n_u={self.n_u:g}, n_v={self.n_v:g}, "
            f"R_s={self.R_s.tolist()}, R_d={self.R_d.tolist()})"
        )

    def core(self, wi, wr) -> np.ndarray:
        """f_r (n, C) of unit pairs above the horizon (eq. 1); edges: :class:`ReferenceBRDF`."""
        cos_i = wi[..., 2]
        cos_r = wr[..., 2]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            # half vector and its projections on u = x, v = y, n = z
            h = wi + wr
            h = h / np.linalg.norm(h, axis=-1, keepdims=True)
            h_u2 = h[..., 0] ** 2
            h_v2 = h[..., 1] ** 2
            cos_h = h[..., 2]
            k_dot_h = np.sum(wi * h, axis=-1)
            # Eq. 4: exponent n_u cos²φ_h + n_v sin²φ_h; its 0/0 at h = n does not matter
            # because (n·h)^e = 1 there for every e
            sin_h2 = h_u2 + h_v2
            exponent = np.where(
                sin_h2 > 0, (self.n_u * h_u2 + self.n_v * h_v2) / np.where(sin_h2 > 0, sin_h2, 1.0), self.n_u
            )
            lobe = np.exp(exponent * np.log(np.maximum(cos_h, 1e-300)))
            # Eq. 2 without the Fresnel factor
            spec = (
                math.sqrt((self.n_u + 1.0) * (self.n_v + 1.0)) / (8.0 * math.pi)
                * lobe / (k_dot_h * np.maximum(cos_i, cos_r))
            )
            # Eq. 3: Schlick's Fresnel, per channel
            fresnel = self.R_s + (1.0 - self.R_s) * schlick_weight(k_dot_h)[..., None]
            # Eq. 5: coupled diffuse term, per channel
            diffuse_shape = (1.0 - (1.0 - 0.5 * cos_i) ** 5) * (1.0 - (1.0 - 0.5 * cos_r) ** 5)
            diffuse = (28.0 / (23.0 * math.pi)) * self.R_d * (1.0 - self.R_s) * diffuse_shape[..., None]
            return spec[..., None] * fresnel + diffuse
