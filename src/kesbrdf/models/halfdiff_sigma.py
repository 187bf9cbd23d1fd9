r"""Per-prediction σ of a ``kes-halfdiff`` model (docs/models.md, "σ of a kes-halfdiff model").

The same form as a ``kes`` table's σ, eq. (K1) of :mod:`kesbrdf.models.kes_sigma`,

.. math::

    \sigma_{\ln f}^2 = n^2 + \bigl(a\, s(2\theta_h)^q\, d_\phi\bigr)^2
        + \bigl((b_0 + b_1 \bar s)\, d_\text{slice}\bigr)^2          \qquad (K1)

with the kes-halfdiff table's own coordinates (:func:`halfdiff_coordinates`):

* n, the noise of ln y, and s, s̄ the data's interpolation error over orientation, are
  computed as for a kes table but over **every** in-plane incidence line θ_i + θ_r =
  const of the measurement (:func:`incidence_lines`): on each, every orientation's rows
  are predicted from its ψ ± 45° neighbours at the same (θ_i, θ_r)
  (:func:`kesbrdf.models.kes_sigma.interpolation_profile`).  Predicting orientation ψ_k
  from ψ_k ± 45° is predicting the half-azimuth slots k and k + 4 from their
  neighbours, which is what the table does over φ_h at fixed (θ_h, θ_d).
* The profile is binned by θ_h, the angle the table holds fixed while it interpolates
  over φ_h; it is stored, like the kes profile, over 2θ_h in 15° bins: in the plane 2θ_h
  is the deviation |θ_r − θ_i|, so the kes bins, field names and checks serve unchanged,
  and at evaluation the profile is read at the pair's 2θ_h.  (θ_h rather than the
  deviation γ off the plane: the table's error between its azimuth slots lives at the
  pair's θ_h, whatever γ the deviation mapping would give it.)
* d_φ is the gap of the pair's half-vector azimuth φ_h to the measured half slots
  (:func:`kesbrdf.models.kes_sigma.azimuth_gap`; slot k is φ_h = k·45°).
* d_slice is the distance of the pair's (θ_h, θ_d) from the measured in-plane support
  (:func:`support_distance`, eq. H1).

(a, q, b₀, b₁) are :data:`HALFDIFF_SIGMA_SCALES`, chosen leave-one-family-out on dense
measurements by benchmarks/bench_calibrate_sigma.py (``kes_halfdiff`` section).  Files
written before have no ``sigma``: they load and refuse σ
(:func:`kesbrdf.validate.uncertainty.predict_sigma`).
"""

from __future__ import annotations

import numpy as np

from kesbrdf.models.kes_sigma import in_plane_at, line_rows, lines_summary
from kesbrdf.models.mappings import to_half_diff
from kesbrdf.models.support import measured_support

__all__ = ["HALFDIFF_SIGMA_SCALES", "SUPPORT_KEYS", "incidence_lines", "halfdiff_support", "sigma_summary",
           "support_distance", "halfdiff_coordinates"]

#: (a, q, b₀, b₁) of eq. (K1) for kes-halfdiff tables, keys as
#: :data:`kesbrdf.models.kes_sigma.KES_SIGMA_SCALES`.  Provenance:
#: benchmarks/bench_calibrate_sigma.py (``kes_halfdiff`` section), fitted on all five
#: reference families at 2 % noise, dense protocol (6°), held-out orientations and both
#: Fig. 6 hemispheres; the leave-one-family-out coverages are in docs/decisions.md
#: ("σ of kes-halfdiff models").
HALFDIFF_SIGMA_SCALES = {"azimuth": 0.5, "azimuth_power": 0.5, "slice": 2.0, "slice_misfit": 4.5}

#: The support fields a kes-halfdiff σ adds to a kes one (checked on load).
SUPPORT_KEYS = ("theta_max_deg",)


def incidence_lines(m, psis) -> list:
    """The in-plane rows of ``m`` at ``psis`` split into incidence lines θ_i + θ_r = const
    (:func:`kesbrdf.models.kes_sigma.line_rows`), one measurement per line."""
    rows = in_plane_at(m, psis)
    sums = np.unique(np.round(m.theta_i[rows] + m.theta_r[rows], 9))
    return [line_rows(m, float(s), psis) for s in sums]


def halfdiff_support(m) -> dict:
    """:func:`kesbrdf.models.support.measured_support` of the in-plane rows ``m`` plus
    ``theta_max_deg``, their largest max(θ_i, θ_r): the measured (θ_h, θ_d) triangle is
    θ_h ≤ θ_d, θ_h + θ_d ≤ θ_max, within the θ_d range."""
    out = measured_support(m)
    out["theta_max_deg"] = float(np.degrees(np.max(np.maximum(m.theta_i, m.theta_r))))
    return out


def sigma_summary(m, model) -> dict | None:
    """The numbers eq. (K1) needs from the in-plane rows ``model`` (a kes-halfdiff fit of
    ``m``) was built from (:func:`kesbrdf.models.kes_sigma.lines_summary` over
    :func:`incidence_lines`, support :func:`halfdiff_support`); None when no orientation
    is predictable from its neighbours."""
    psis = np.radians([0.0, 45.0, 90.0, 135.0][:model.orientations])
    rows = in_plane_at(m, psis)
    if not rows.any():
        return None
    return lines_summary(incidence_lines(m, psis), halfdiff_support(m.subset(rows)))


def support_distance(support: dict, wi, wr) -> np.ndarray:
    r"""d_slice of a kes-halfdiff table (radians): how far a pair's (θ_h, θ_d) lies from
    the measured in-plane support,

    .. math::

        d_\text{slice}^2 = \operatorname{dist}(\theta_d, [\theta_d^-, \theta_d^+])^2
            + \max(0, \theta_h - \theta_d)^2 + \max(0, \theta_h + \theta_d - \theta_\max)^2
            \qquad (H1)

    In the plane θ_i = θ_d − θ_h and max(θ_i, θ_r) = θ_h + θ_d, so the second term is how
    far the light would have to be past the normal (light and viewer on one side, which
    the table reads at θ_i = 0) and the third how far past the largest measured angle
    (read at θ_max): where the fit clamps θ_d (:mod:`kesbrdf.models.halfdiff`, step 3).
    """
    _, theta_h, theta_d = to_half_diff(wi, wr)
    lo, hi = np.radians(support["theta_d_deg"])
    theta_max = np.radians(support["theta_max_deg"])
    d_td = np.maximum(lo - theta_d, 0.0) + np.maximum(theta_d - hi, 0.0)
    d_same = np.maximum(theta_h - theta_d, 0.0)
    d_far = np.maximum(theta_h + theta_d - theta_max, 0.0)
    return np.sqrt(d_td**2 + d_same**2 + d_far**2)


def halfdiff_coordinates(model, wi, wr):
    """(φ_h, 2θ_h, d_slice) of eq. (K1) for a kes-halfdiff table (module docstring)."""
    phi_h, theta_h, _ = to_half_diff(wi, wr)
    return phi_h, 2.0 * theta_h, support_distance(model.sigma["support"], wi, wr)
