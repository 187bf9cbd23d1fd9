r"""Anisotropic Ward BRDF (G. J. Ward, "Measuring and Modeling Anisotropic
Reflection", SIGGRAPH 1992, eq. 5), used as dense ground truth.

.. math::

    f_r = \frac{\rho_d}{\pi} + \rho_s\,
    \frac{\exp\!\left[-\tan^2\theta_h\left(\cos^2\phi_h/\alpha_x^2 + \sin^2\phi_h/\alpha_y^2\right)\right]}
         {4\pi\,\alpha_x\alpha_y\sqrt{\cos\theta_i\cos\theta_r}}

α_x is the slope spread along x (the warp), α_y along y (the weft).  The model is
reciprocal.  Its energy stays below 1 for moderate α and ρ_d + ρ_s ≤ 1 (Ward's own
normalisation is approximate at grazing angles).
"""

from __future__ import annotations

import numpy as np

from kesbrdf.references.base import ReferenceBRDF, default_channels

__all__ = ["AnisotropicWard"]


class AnisotropicWard(ReferenceBRDF):
    """Callable anisotropic Ward BRDF; ``rho_d`` and ``rho_s`` may be per channel.

    >>> w = AnisotropicWard(0.1, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.04)
    >>> w.channels
    ('R', 'G', 'B')
    """

    def __init__(self, alpha_x: float, alpha_y: float, rho_d=0.1, rho_s=0.05, channels=None):
        self.alpha_x = float(alpha_x)
        self.alpha_y = float(alpha_y)
        rho_d = np.atleast_1d(np.asarray(rho_d, float))
        rho_s = np.atleast_1d(np.asarray(rho_s, float))
        n = max(rho_d.size, rho_s.size)
        self.rho_d = np.broadcast_to(rho_d, (n,)).copy()
        self.rho_s = np.broadcast_to(rho_s, (n,)).copy()
        if channels is None:
            channels = default_channels(n, "band_")
        self.channels = tuple(channels)

    def params(self) -> dict:
        return {
            "reference": "ward",
            "alpha_x": self.alpha_x,
            "alpha_y": self.alpha_y,
            "rho_d": self.rho_d.tolist(),
            "rho_s": self.rho_s.tolist(),
        }

    def core(self, wi, wr) -> np.ndarray:
        """f_r (n, C) of unit pairs above the horizon; edges: :class:`ReferenceBRDF`."""
        h = wi + wr
        with np.errstate(over="ignore", under="ignore"):
            exponent = -((h[..., 0] / self.alpha_x) ** 2 + (h[..., 1] / self.alpha_y) ** 2) / (h[..., 2] ** 2)
            spec = np.exp(exponent) / (4 * np.pi * self.alpha_x * self.alpha_y * np.sqrt(wi[..., 2] * wr[..., 2]))
        return self.rho_d / np.pi + self.rho_s * spec[..., None]
