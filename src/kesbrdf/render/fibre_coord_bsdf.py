r"""The ``kesbrdf_fibre_coord`` BSDF: a ``fibre-coord`` model file as a Mitsuba 3 plugin.

Evaluation is :meth:`kesbrdf.models.fibre_coord.FibreCoordModel.evaluate` in Dr.Jit (single
precision): the model's (C1) (:mod:`kesbrdf.models.fibre_coord`)

.. math::

    f_\text{prior} = k_d e^{\delta_0} + e^{d(\theta_d)} \sum_{k\in\{\text{warp},\text{weft}\}}
          e^{\delta_k}\, F_k(\omega_i, \omega_r)\; e^{p_k(u^*_k)}\; e^{n_k(\phi_k)}      \qquad (C1)

then the KES residual r^τ and the energy scale g(ω_i) g(ω_r) exactly as the
``kesbrdf_prior`` plugin (:mod:`kesbrdf.render.prior_bsdf`), whose class this one extends:

* F_k, family k's part of the fitted woven-cloth prior, is
  :meth:`kesbrdf.render.prior_bsdf.PriorDrJit.parts` (the same Dr.Jit code that draws a
  ``fibre-prior`` model);
* the fibre coordinates of family k (α = 0 warp, 90° weft, no axis offset, as
  :func:`kesbrdf.models.fibre_coord.fibre_coordinates`): the tilt u* = atan2(h'_y, h'_z) and
  the azimuth φ between the projections of ω_i and ω_r on the plane ⟂ t = (0, cos u*, −sin u*),
  and θ_d = ∠(ω_i, h); φ and θ_d are taken as atan2(|a×b|, a·b), which keeps float32
  accuracy where acos loses it (near 0 and 180°);
* p_k, n_k, d are read linearly between their fixed nodes
  (:data:`~kesbrdf.models.fibre_coord.U_NODES_DEG`, :data:`~kesbrdf.models.fibre_coord.PHI_NODES_DEG`,
  :data:`~kesbrdf.models.fibre_coord.TD_NODES_DEG`), clamped at the ends, and every
  exponent is clipped at ±30 as the numpy model does.

Colour, sampling, two-sided mirroring and the parameters (``filename``, ``base_color``,
``lobe_tint``, ``two_sided``, ``sampling``) are those of ``kesbrdf_prior``: the body is the
corrected k_d e^{δ_0}, the sampling density :func:`kesbrdf.render.prior_bsdf.lobe_table`
of this model's own lobe (so the corrected highlights are importance-sampled).
"""

from __future__ import annotations

import numpy as np

import drjit as dr
import mitsuba as mi

from kesbrdf.render.jit import opaque_rgb
from kesbrdf.render.prior_bsdf import FibrePriorBSDF, PriorDrJit, family_frame, as_rgb

__all__ = ["FibreCoordBSDF", "register", "PLUGIN"]

#: Name of the plugin.
PLUGIN = "kesbrdf_fibre_coord"
#: Clip of the log corrections, as ``CoordPrior._f_and_jacobian``.
_LOG_CLIP = 30.0


def _angle(a, b):
    """∠(a, b) of tuples or vectors in [0, π]: atan2(|a×b|, a·b) (float32-accurate everywhere)."""
    cx = a[1] * b[2] - a[2] * b[1]
    cy = a[2] * b[0] - a[0] * b[2]
    cz = a[0] * b[1] - a[1] * b[0]
    return dr.atan2(dr.sqrt(cx * cx + cy * cy + cz * cz), a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


class _PiecewiseLinear:
    """A log correction on uniform nodes (degrees), read at x (radians), clamped at the ends
    (as :func:`kesbrdf.models.fibre_coord._hat`)."""

    def __init__(self, nodes_deg, values):
        nodes = np.radians(np.asarray(nodes_deg, float))
        self.x0, self.inv_dx, self.k = float(nodes[0]), float(1.0 / (nodes[1] - nodes[0])), int(nodes.size)
        self.values = mi.Float(np.asarray(values, np.float64))

    def __call__(self, x):
        t = dr.clip((x - self.x0) * self.inv_dx, 0.0, float(self.k - 1))
        i = dr.minimum(mi.UInt32(dr.floor(t)), self.k - 2)
        frac = t - mi.Float(i)
        return dr.gather(mi.Float, self.values, i) * (1.0 - frac) + dr.gather(mi.Float, self.values, i + 1) * frac


class _CoordPrior:
    """(C1) of a :class:`kesbrdf.models.fibre_coord.CoordPrior` in Dr.Jit (module docstring)."""

    def __init__(self, prior):
        from kesbrdf.models.fibre_coord import FAMILIES, PHI_NODES_DEG, TD_NODES_DEG, U_NODES_DEG

        self.base = PriorDrJit(prior.base)
        sl, theta = prior.slices(), prior.theta
        #: the corrected k_d e^{δ_0} (RGB): the body of the recolouring
        self.kd = self.base.kd * as_rgb(np.exp(theta[sl["kd"]]))
        self.kd_c = opaque_rgb(self.kd)
        self.families = []
        for fam, alpha in FAMILIES:
            self.families.append({"alpha": alpha, "scale": opaque_rgb(as_rgb(np.exp(theta[sl[f"{fam}_ks"]]))),
                                  "p": _PiecewiseLinear(U_NODES_DEG, theta[sl[f"{fam}_p"]]),
                                  "n": _PiecewiseLinear(PHI_NODES_DEG, theta[sl[f"{fam}_n"]])})
        self.d = _PiecewiseLinear(TD_NODES_DEG, theta[sl["d"]]) if prior.free_theta_d else None

    def __call__(self, wi, wr):
        """f_prior of (C1) (Color3f) for unit directions above the horizon."""
        h = dr.normalize(wi + wr)
        log_d = self.d(_angle(wi, h)) if self.d is not None else 0.0
        f = mi.Color3f(self.kd_c)
        for fam, part in zip(self.families, self.base.parts(wi, wr)):
            hx, hy, hz = family_frame(h, fam["alpha"])
            i, r = family_frame(wi, fam["alpha"]), family_frame(wr, fam["alpha"])
            u = dr.atan2(hy, hz)
            t = (0.0, dr.cos(u), -dr.sin(u))
            di, dq = i[0] * t[0] + i[1] * t[1] + i[2] * t[2], r[0] * t[0] + r[1] * t[1] + r[2] * t[2]
            phi = _angle([i[k] - di * t[k] for k in range(3)], [r[k] - dq * t[k] for k in range(3)])
            log_c = dr.clip(fam["p"](u) + fam["n"](phi), -_LOG_CLIP, _LOG_CLIP)
            if self.d is not None:
                log_c = log_c + dr.clip(log_d, -_LOG_CLIP, _LOG_CLIP)
            f = f + fam["scale"] * (dr.maximum(part, 0.0) * dr.exp(log_c))
        return f


class FibreCoordBSDF(FibrePriorBSDF):
    """Mitsuba BSDF of a ``fibre-coord`` model (module docstring)."""

    PLUGIN = PLUGIN
    KIND = "fibre-coord"

    @staticmethod
    def make_prior(prior):
        return _CoordPrior(prior)


def register() -> None:
    """Register the plugin under the name ``kesbrdf_fibre_coord`` (idempotent)."""
    mi.register_bsdf(PLUGIN, lambda props: FibreCoordBSDF(props))
