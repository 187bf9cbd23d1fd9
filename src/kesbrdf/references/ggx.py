r"""Anisotropic GGX (Trowbridge–Reitz) microfacet BRDF over a Lambertian body: a
non-fibre control family for the leave-one-family-out library.

Sources: B. Walter, S. Marschner, H. Li, K. Torrance, "Microfacet Models for
Refraction through Rough Surfaces", EGSR 2007 (the GGX distribution, eq. 33, and the
microfacet BRDF, eq. 20); E. Heitz, "Understanding the Masking-Shadowing Function in
Microfacet-Based BRDFs", JCGT 3(2), 2014 (the anisotropic distribution, eq. 85, its
Smith Λ, eq. 86, and the height-correlated masking-shadowing G2, eq. 99).  Equation
numbers are those of the two papers as cited by their readers; the formulas are the
standard ones and are checked by this module's tests (normalisation of D, the weak
white furnace of G1, reciprocity, white-furnace albedo ≤ 1).

.. math::

    f_r = k_s\,\frac{F(\omega_i\cdot h)\,D(h)\,G_2(\omega_i, \omega_r)}{4\cos\theta_i\cos\theta_r}
        + \frac{\rho_d}{\pi}\,\bigl(1 - F(\cos\theta_i)\bigr)\bigl(1 - F(\cos\theta_r)\bigr)

    D(h) = \frac{1}{\pi\alpha_x\alpha_y\,\bigl(h_x^2/\alpha_x^2 + h_y^2/\alpha_y^2 + h_z^2\bigr)^2}
    \qquad
    \Lambda(\omega) = \frac{-1 + \sqrt{1 + (\alpha_x^2\omega_x^2 + \alpha_y^2\omega_y^2)/\omega_z^2}}{2}

    G_2 = \frac{1}{1 + \Lambda(\omega_i) + \Lambda(\omega_r)}

F is the unpolarised Fresnel reflectance of a dielectric of index η
(:func:`kesbrdf.optics.fresnel_dielectric`).  The body term is the light that the
interface lets in and out, both times weighted by 1 − F on the macro normal; it is
reciprocal and its albedo is ρ_d (1 − F(cos θ_r)) (1 − F̄) ≤ ρ_d, with F̄ the
cosine-weighted hemispherical mean of F.

α_x is the roughness along x (the warp), α_y along y (the weft).  The BRDF is a
surface with no fibres in it: its highlight is a single lobe about the mirror
direction, stretched by the anisotropy, never a cone.  Microflake/SGGX volumes are not
this model (a GGX *surface* distribution; no volume, no fibres).
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import KesbrdfError
from kesbrdf.optics import fresnel_dielectric
from kesbrdf.references.base import ReferenceBRDF, default_channels

__all__ = ["AnisotropicGGX", "ggx_ndf", "smith_lambda"]


class GGXError(KesbrdfError):
    """Invalid parameters for the anisotropic GGX reference."""


def ggx_ndf(h, alpha_x: float, alpha_y: float) -> np.ndarray:
    """D(h) of the anisotropic GGX distribution (Heitz 2014 eq. 85), 1/sr; 0 for h_z ≤ 0.

    ``h`` (..., 3) unit vectors.  ∫ D(h) cos θ_h dω_h = 1 over the upper hemisphere.

    >>> round(float(ggx_ndf([0.0, 0.0, 1.0], 0.5, 0.5)), 6) == round(1 / (math.pi * 0.25), 6)
    True
    """
    h = np.asarray(h, float)
    q = (h[..., 0] / alpha_x) ** 2 + (h[..., 1] / alpha_y) ** 2 + h[..., 2] ** 2
    with np.errstate(divide="ignore"):
        d = 1.0 / (math.pi * alpha_x * alpha_y * q * q)
    return np.where(h[..., 2] > 0, d, 0.0)


def smith_lambda(w, alpha_x: float, alpha_y: float) -> np.ndarray:
    """Smith Λ(ω) of the anisotropic GGX distribution (Heitz 2014 eq. 86), ω_z > 0.

    >>> float(smith_lambda([0.0, 0.0, 1.0], 0.3, 0.7))
    0.0
    """
    w = np.asarray(w, float)
    a2 = (alpha_x * w[..., 0]) ** 2 + (alpha_y * w[..., 1]) ** 2
    return 0.5 * (np.sqrt(1.0 + a2 / (w[..., 2] ** 2)) - 1.0)


class AnisotropicGGX(ReferenceBRDF):
    """Anisotropic GGX specular lobe over a Lambertian body (module docstring).

    Parameters
    ----------
    alpha_x, alpha_y : float
        GGX roughness along x (warp) and y (weft), in [1e-3, 1].
    eta : float
        Index of refraction of the interface, in (1, 3] (F(0°) = 0.04 at 1.5).
    rho_d : float or array_like (C,)
        Body albedo per channel, in [0, 1].
    k_s : float or array_like (C,)
        Weight of the specular lobe per channel, in [0, 1] (1: the whole surface is the
        interface).

    >>> g = AnisotropicGGX(0.1, 0.3, eta=1.5, rho_d=[0.4, 0.2, 0.1])
    >>> g.channels
    ('R', 'G', 'B')
    """

    error = GGXError

    def __init__(self, alpha_x: float, alpha_y: float, eta: float = 1.5, rho_d=0.3, k_s=1.0, channels=None):
        for name, value, ok_range, text in (
            ("alpha_x", alpha_x, lambda v: 1e-3 <= v <= 1.0, "[0.001, 1]"),
            ("alpha_y", alpha_y, lambda v: 1e-3 <= v <= 1.0, "[0.001, 1]"),
            ("eta", eta, lambda v: 1.0 < v <= 3.0, "(1, 3]"),
        ):
            if not (np.isscalar(value) and np.isfinite(value) and ok_range(float(value))):
                raise GGXError(f"AnisotropicGGX {name}: expected a number in {text}, got {value!r}")
        rho_d = np.atleast_1d(np.asarray(rho_d, float))
        k_s = np.atleast_1d(np.asarray(k_s, float))
        if rho_d.ndim != 1 or k_s.ndim != 1:
            raise GGXError(f"AnisotropicGGX rho_d, k_s: expected scalars or per-channel lists, got shapes "
                           f"{rho_d.shape} and {k_s.shape}")
        try:
            rho_d, k_s = np.broadcast_arrays(rho_d, k_s)
        except ValueError:
            raise GGXError(f"AnisotropicGGX rho_d, k_s: expected the same number of channels, got "
                           f"{rho_d.size} and {k_s.size}") from None
        for name, value in (("rho_d", rho_d), ("k_s", k_s)):
            if not np.all(np.isfinite(value) & (value >= 0) & (value <= 1)):
                raise GGXError(f"AnisotropicGGX {name}: expected values in [0, 1], got {value.tolist()}")
        self.alpha_x = float(alpha_x)
        self.alpha_y = float(alpha_y)
        self.eta = float(eta)
        self.rho_d = rho_d.copy()
        self.k_s = k_s.copy()
        self.channels = tuple(channels) if channels is not None else default_channels(self.rho_d.size)
        if len(self.channels) != self.rho_d.size:
            raise GGXError(f"AnisotropicGGX channels: expected {self.rho_d.size} names, got {len(self.channels)}")

    def params(self) -> dict:
        """JSON-ready description (recorded by the virtual gonioreflectometer)."""
        return {"reference": "ggx", "alpha_x": self.alpha_x, "alpha_y": self.alpha_y, "eta": self.eta,
                "rho_d": self.rho_d.tolist(), "k_s": self.k_s.tolist()}

    def __repr__(self) -> str:
        return (f"AnisotropicGGX(alpha_x={self.alpha_x:g}, alpha_y={self.alpha_y:g}, eta={self.eta:g}, "
                f"rho_d={self.rho_d.tolist()}, k_s={self.k_s.tolist()})")

    def specular(self, wi, wr) -> np.ndarray:
        """The microfacet lobe F D G2 / (4 cos θ_i cos θ_r) (Walter 2007 eq. 20), k_s = 1, shape (n,)."""
        h = wi + wr
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        d = ggx_ndf(h, self.alpha_x, self.alpha_y)
        g2 = 1.0 / (1.0 + smith_lambda(wi, self.alpha_x, self.alpha_y) + smith_lambda(wr, self.alpha_x, self.alpha_y))
        f = fresnel_dielectric(np.sum(wi * h, axis=-1), self.eta)
        return f * d * g2 / (4.0 * wi[..., 2] * wr[..., 2])

    def core(self, wi, wr) -> np.ndarray:
        """f_r (n, C) of unit pairs above the horizon; edges: :class:`ReferenceBRDF`."""
        spec = self.specular(wi, wr)
        body = (1.0 - fresnel_dielectric(wi[..., 2], self.eta)) * (1.0 - fresnel_dielectric(wr[..., 2], self.eta))
        return self.k_s * spec[..., None] + (self.rho_d / math.pi) * body[..., None]
