"""Where a fit saw data, and how far a direction pair is from it (eqs. U2 of
:mod:`kesbrdf.models.fibre_prior`), and the cap of a reported σ of ln f.

Shared by the σ of the prior-based kinds (:func:`kesbrdf.models.fibre_prior.predict_with_uncertainty`)
and of kes models (:mod:`kesbrdf.models.kes_sigma`); kept below both so neither imports the other.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.models.mappings import to_phi_gamma

__all__ = ["MAX_SIGMA_LOG", "theta_d", "measured_support", "support_distance", "support_distance_parts"]

#: Largest σ of ln f reported (a factor e³ ≈ 20): beyond it the number means "unknown".
MAX_SIGMA_LOG = 3.0


def theta_d(wi, wr):
    """θ_d, half the angle between ω_i and ω_r (radians)."""
    c = np.clip(np.sum(wi * wr, axis=-1), -1.0, 1.0)
    return 0.5 * np.arccos(c)


def measured_support(m) -> dict:
    """Where ``m`` holds data: its θ_d range, largest deviation γ and light azimuths ψ
    (the orientations, mod 180°), all in degrees."""
    td = np.degrees(theta_d(m.wi, m.wr))
    _, gamma = to_phi_gamma(m.wi, m.wr, "deviation")
    psi = np.unique(np.round(np.degrees(np.arctan2(m.wi[:, 1], m.wi[:, 0])) % 180.0, 6))
    return {"theta_d_deg": [float(np.min(td)), float(np.max(td))], "gamma_max_deg": float(np.degrees(np.max(gamma))),
            "psi_deg": [float(v) for v in psi]}


def support_distance(support: dict, wi, wr) -> np.ndarray:
    r"""Distance (radians) of direction pairs from the measured support, eq. (U2):

    .. math::

        d^2 = \operatorname{dist}(\theta_d, [\theta_d^-, \theta_d^+])^2
            + \max(0, \gamma - \gamma_\max)^2
            + \bigl(\sin\theta_i \min_k |\phi_i - \psi_k|_{180°}\bigr)^2

    θ_d outside the measured θ_d range, γ beyond the largest measured deviation, and the
    light's azimuth from the nearest measured orientation ψ_k (mod 180°, as arc length:
    the azimuth does not matter at normal incidence).  A support without ``psi_deg``
    (written before it was stored) has no azimuth term.  The two parts separately:
    :func:`support_distance_parts`.
    """
    d_slice, d_psi = support_distance_parts(support, wi, wr)
    return np.hypot(d_slice, d_psi)


def support_distance_parts(support: dict, wi, wr):
    """(d_slice, d_ψ) of eq. (U2), radians: the distance off the measured slice (θ_d
    outside its range, γ beyond the largest deviation) and sin θ_i times the light's
    azimuth gap to the nearest measured orientation (0 without ``psi_deg``)."""
    wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
    lo, hi = np.radians(support["theta_d_deg"])
    td = theta_d(wi, wr)
    _, gamma = to_phi_gamma(wi, wr, "deviation")
    d_td = np.maximum(lo - td, 0.0) + np.maximum(td - hi, 0.0)
    d_g = np.maximum(gamma - math.radians(support["gamma_max_deg"]), 0.0)
    d_psi = np.zeros_like(td)
    psi = np.radians(np.asarray(support.get("psi_deg", []), float))
    if psi.size:
        phi_i = np.arctan2(wi[..., 1], wi[..., 0])
        gap = np.abs((phi_i[..., None] - psi + np.pi / 2) % np.pi - np.pi / 2).min(axis=-1)
        d_psi = np.sqrt(np.clip(1.0 - wi[..., 2] ** 2, 0.0, 1.0)) * gap
    return np.sqrt(d_td**2 + d_g**2), d_psi
