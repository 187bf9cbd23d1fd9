r"""Per-prediction σ of a ``kes`` model, from what its own data say (docs/models.md, "σ of a kes model").

A KES table passes through the measured samples; what it does between the measured
orientations and off the measured slice is interpolation and extrapolation, whose error
the table alone cannot know.  The measurement can say part of it, and that part is
computed at fit time (:func:`sigma_summary`) and stored in the model file (a few
numbers, field ``sigma`` of the kes payload):

* n, the noise of ln y: the median relative uncertainty σ/|y| of the measurement's
  uncertainty column, else a robust estimate from the roughness of each line
  (:func:`kesbrdf.models.lines.relative_noise`);
* s(γ), the interpolation error over orientation the data show: every measured
  orientation ψ_k is predicted from its neighbours ψ_k ± 45° (linear interpolation over
  ψ, :func:`kesbrdf.models.lines.orientation_interpolation_predictions`, the
  leave-one-orientation-out that is possible for the warp and weft too, which the KES
  form itself cannot drop), and the RMS of ln(prediction/y) is taken in bins of |γ| of
  :data:`GAMMA_BIN_DEG` (eq. K2); s̄ is the RMS over all of them;
* the support: the measured θ_d range, largest deviation and orientations
  (:func:`kesbrdf.models.support.measured_support`).

At evaluation (eq. K1):

.. math::

    \sigma_{\ln f}^2 = n^2 + \bigl(a\, s(\gamma)^q\, d_\phi\bigr)^2
        + \bigl((b_0 + b_1 \bar s)\, d_\text{slice}\bigr)^2          \qquad (K1)

with d_φ the gap (radians) of the pair's deviation azimuth φ to the nearest measured
half-azimuth (:func:`azimuth_gap`: the table is interpolated over φ at each γ, so this
is where its interpolation error lives; the fibre prior's d_ψ = sin θ_i·gap vanishes at
normal incidence, where a KES table still interpolates) and d_slice the distance off the
measured slice (θ_d outside its range, γ beyond the largest deviation,
:func:`kesbrdf.models.support.support_distance_parts`).  (a, q, b₀, b₁) are
:data:`KES_SIGMA_SCALES`, chosen leave-one-family-out by
benchmarks/bench_calibrate_sigma.py.  σ_ln f is capped at
:data:`kesbrdf.models.support.MAX_SIGMA_LOG`.

Files written before the summary have ``sigma`` absent: they still load and still
refuse σ (:func:`kesbrdf.validate.uncertainty.predict_sigma`).

The ``kes-halfdiff`` kind uses the same summary, check, combination and capability
(:class:`StoredSigma`) with its own coordinates (φ_h, 2θ_h, its d_slice) and scales
(:mod:`kesbrdf.models.halfdiff_sigma`): each kind supplies ``sigma_coordinates(wi, wr)``
and ``sigma_scales``.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import ModelError, where
from kesbrdf.models import interpolation as kes
from kesbrdf.models.lines import line as orientation_line, orientation_interpolation_predictions, relative_noise
from kesbrdf.models.mappings import to_phi_gamma
from kesbrdf.models.support import MAX_SIGMA_LOG, measured_support, support_distance_parts

__all__ = ["KES_SIGMA_SCALES", "GAMMA_BIN_DEG", "in_plane_at", "line_rows", "interpolation_profile",
           "noise_level", "lines_summary", "sigma_summary", "check_summary", "azimuth_gap", "kes_coordinates", "sigma_inputs",
           "combine", "predict_kes_sigma", "StoredSigma"]

#: Width of the |γ| bins of the interpolation-error profile s(γ), degrees (eq. K2):
#: six bins over 0–90°, each holding ≥ 3 samples of each line at the paper's 5° step.
GAMMA_BIN_DEG = 15.0

#: (a, q, b₀, b₁) of eq. (K1): ``azimuth`` a and ``azimuth_power`` q of a·s(γ)^q·d_φ,
#: ``slice`` b₀ and ``slice_misfit`` b₁ of (b₀ + b₁ s̄)·d_slice.  Provenance:
#: benchmarks/bench_calibrate_sigma.py (``kes`` section), fitted on all five reference
#: families (Irawan–Marschner and Sadeghi presets, Ward, Ashikhmin–Shirley, the RGL felt)
#: at 2 % noise, paper protocol, held-out orientations and both Fig. 6 hemispheres;
#: the leave-one-family-out coverages are in docs/decisions.md ("σ of kes models").
KES_SIGMA_SCALES = {"azimuth": 1.0, "azimuth_power": 1.0, "slice": 0.3, "slice_misfit": 3.0}


def in_plane_at(m, psis) -> np.ndarray:
    """Mask of the in-plane rows of ``m`` at the orientations ``psis`` (radians)."""
    at = np.zeros(len(m), bool)
    for psi in psis:
        at |= np.abs(np.asarray(m.psi, float) - psi) < math.radians(0.5)
    return m.is_in_plane & at


def line_rows(m, line_sum: float, psis):
    """The in-plane rows of ``m`` on the incidence line θ_i + θ_r = ``line_sum`` at the
    orientations ``psis`` (radians): the samples a KES table was built from."""
    return m.subset(in_plane_at(m, psis) & (np.abs(m.theta_i + m.theta_r - line_sum) < 1e-6))


def interpolation_profile(lines):
    """(s̄, s(γ) per |γ| bin) of eq. (K2) over the incidence lines ``lines`` (measurements
    of one line θ_i + θ_r = const each: the kes table's one line, or every line of a
    dense measurement for ``kes-halfdiff``), or None when no orientation can be predicted
    from its two neighbours (3 orientations still predict 45° from 0° and 90°).  γ is
    the in-plane deviation |θ_r − θ_i|."""
    r, g = [], []
    for m in lines:
        for one, pred in orientation_interpolation_predictions(m).values():
            ok = np.all(np.isfinite(pred), axis=-1)
            y = one[1][ok]
            eps = 1e-4 * max(float(np.max(np.abs(one[1]))), 1e-300)
            r.append(np.log(np.maximum(pred[ok], 0) + eps) - np.log(np.maximum(y, 0) + eps))
            g.append(np.repeat(np.abs(one[2] - one[0])[ok][:, None], y.shape[1], axis=1))
    if not r or not sum(x.size for x in r):
        return None
    r, g = np.concatenate(r).ravel(), np.concatenate(g).ravel()
    n_bins = int(math.ceil(90.0 / GAMMA_BIN_DEG))
    k = np.minimum((g / GAMMA_BIN_DEG).astype(int), n_bins - 1)
    prof = np.array([np.sqrt(np.mean(r[k == j] ** 2)) if np.any(k == j) else np.nan for j in range(n_bins)])
    filled = np.isfinite(prof)
    centres = (np.arange(n_bins) + 0.5) * GAMMA_BIN_DEG
    prof = np.interp(centres, centres[filled], prof[filled])  # empty bins: the nearest filled one
    return float(np.sqrt(np.mean(r**2))), prof


def noise_level(lines) -> float:
    """n of eq. (K1): the median relative noise σ/|y| over the orientations of the
    incidence lines ``lines`` (:func:`kesbrdf.models.lines.relative_noise`: the
    uncertainty column, else the roughness of each line)."""
    vals = []
    for m in lines:
        for p in (0.0, 45.0, 90.0, 135.0):
            one = orientation_line(m, p)
            if one is not None:
                vals.append(np.ravel(relative_noise(one)))
    return float(np.median(np.concatenate(vals))) if vals else 0.0


def lines_summary(lines, support: dict) -> dict | None:
    """``{"noise", "s", "s_gamma", "gamma_bin_deg", "support"}`` of eq. (K1) from the
    incidence lines a table was built from and its measured ``support``; None when no
    orientation is predictable from its neighbours."""
    prof = interpolation_profile(lines)
    if prof is None:
        return None
    s, s_gamma = prof
    return {"noise": noise_level(lines), "s": s, "s_gamma": [float(v) for v in s_gamma],
            "gamma_bin_deg": GAMMA_BIN_DEG, "support": support}


def sigma_summary(m, model) -> dict | None:
    """The numbers eq. (K1) needs, from the samples ``model`` (a ``kes`` fit of ``m``) was
    built from: ``{"noise", "s", "s_gamma", "gamma_bin_deg", "support"}``; None when
    they cannot be had (no orientation predictable from its neighbours)."""
    psis = np.radians([0.0, 45.0, 90.0, 135.0][:model.orientations])
    line = line_rows(m, model.line_sum, psis)
    if len(line) == 0:
        return None
    return lines_summary([line], measured_support(line))


def check_summary(doc, source=None, support_keys=()) -> dict:
    """The ``sigma`` field of a model file, checked (finite, non-negative numbers and a
    support, with the extra number fields ``support_keys`` the kind's distance needs); a
    malformed one is a one-line ModelError."""
    try:
        sup = doc["support"]
        out = {"noise": float(doc["noise"]), "s": float(doc["s"]), "s_gamma": [float(v) for v in doc["s_gamma"]],
               "gamma_bin_deg": float(doc["gamma_bin_deg"]),
               "support": {"theta_d_deg": [float(v) for v in sup["theta_d_deg"]],
                           "gamma_max_deg": float(sup["gamma_max_deg"]),
                           "psi_deg": [float(v) for v in sup["psi_deg"]],
                           **{key: float(sup[key]) for key in support_keys}}}
    except (KeyError, TypeError, ValueError) as exc:
        fields = ", ".join(("theta_d_deg", "gamma_max_deg", "psi_deg") + tuple(support_keys))
        raise ModelError(f"{where(source)}sigma: expected noise, s, s_gamma, gamma_bin_deg and support "
                         f"({fields}) ({exc})") from None
    numbers = [out["noise"], out["s"], out["gamma_bin_deg"], *out["s_gamma"], *out["support"]["theta_d_deg"],
               out["support"]["gamma_max_deg"], *out["support"]["psi_deg"], *(out["support"][k] for k in support_keys)]
    if (not all(map(math.isfinite, numbers)) or min(numbers[:2] + out["s_gamma"]) < 0 or out["gamma_bin_deg"] <= 0
            or not out["s_gamma"] or len(out["support"]["theta_d_deg"]) != 2):
        raise ModelError(f"{where(source)}sigma: expected finite non-negative noise, s, s_gamma (at least one bin), "
                         "a positive gamma_bin_deg and theta_d_deg [lo, hi]")
    return out


def azimuth_gap(phi, orientations: int) -> np.ndarray:
    """d_φ of eq. (K1): the circular distance (radians) of azimuths φ (the deviation
    azimuth of a kes table, the half-vector azimuth φ_h of a kes-halfdiff one) to the
    nearest measured half-azimuth (:data:`kesbrdf.models.interpolation.HALF_AZIMUTHS` of
    the orientations used)."""
    az = kes.HALF_AZIMUTHS[kes.half_slots(orientations)]
    d = np.abs((np.asarray(phi, float)[..., None] - az + np.pi) % (2 * np.pi) - np.pi)
    return d.min(axis=-1)


def kes_coordinates(model, wi, wr):
    """(φ, γ, d_slice) of eq. (K1) for a kes table: (φ, γ) in the mapping the table is read
    with (its ``default_mapping``: the half-vector azimuth and 2θ_h for new fits, the
    deviation azimuth and deviation for older files; :func:`kesbrdf.models.mappings.to_phi_gamma`)
    and the distance off the measured slice (:func:`kesbrdf.models.support.support_distance_parts`)."""
    mapping = getattr(model, "default_mapping", "deviation")
    phi, gamma = to_phi_gamma(wi, wr, mapping if mapping in ("deviation", "halfvector") else "deviation")
    d_slice, _ = support_distance_parts(model.sigma["support"], wi, wr)
    return phi, gamma, d_slice


def sigma_inputs(model, wi, wr) -> dict:
    """The per-pair ingredients of eq. (K1), each (N, 1): ``noise``, ``s_gamma`` (the
    profile read at the pair's γ, linearly between bin centres, held beyond them),
    ``d_phi``, ``s`` and ``d_slice``; (φ, γ, d_slice) are the kind's own
    (``model.sigma_coordinates``: :func:`kes_coordinates`, or
    :func:`kesbrdf.models.halfdiff_sigma.halfdiff_coordinates`)."""
    summ = model.sigma
    phi, gamma, d_slice = model.sigma_coordinates(wi, wr)
    step = summ["gamma_bin_deg"]
    centres = (np.arange(len(summ["s_gamma"])) + 0.5) * step
    s_g = np.interp(np.degrees(gamma), centres, summ["s_gamma"])
    n = gamma.shape[0]
    return {"noise": np.full((n, 1), summ["noise"]), "s_gamma": s_g[:, None],
            "d_phi": azimuth_gap(phi, model.orientations)[:, None], "s": np.full((n, 1), summ["s"]),
            "d_slice": d_slice[:, None]}


def combine(parts: dict, scales=None, defaults=None) -> np.ndarray:
    """σ of ln f of eq. (K1) from :func:`sigma_inputs`, capped at MAX_SIGMA_LOG; ``scales``
    override ``defaults`` (:data:`KES_SIGMA_SCALES` unless given)."""
    k = dict(KES_SIGMA_SCALES if defaults is None else defaults, **(scales or {}))
    var = (parts["noise"] ** 2 + (k["azimuth"] * parts["s_gamma"] ** k["azimuth_power"] * parts["d_phi"]) ** 2
           + ((k["slice"] + k["slice_misfit"] * parts["s"]) * parts["d_slice"]) ** 2)
    return np.minimum(np.sqrt(var), MAX_SIGMA_LOG)


def predict_kes_sigma(model, wi, wr, scales=None):
    """``(f, σ, σ_ln f)``, each (N, C), of a table model with a sigma summary (eq. K1), at
    the kind's own scales (``model.sigma_scales``) unless ``scales`` override them."""
    wi = np.asarray(wi, float).reshape(-1, 3)
    wr = np.asarray(wr, float).reshape(-1, 3)
    wi, wr = np.broadcast_arrays(wi, wr)
    f = np.asarray(model.evaluate(wi, wr), float)
    f = np.where(np.isfinite(f), f, 0.0)
    sigma_log = combine(sigma_inputs(model, wi, wr), scales, model.sigma_scales)
    sigma_log = np.broadcast_to(sigma_log, f.shape).copy()
    return f, np.maximum(f * sigma_log, 0.0), sigma_log


class StoredSigma:
    """The σ capability (:mod:`kesbrdf.models.base`) of a table kind whose file stores the
    summary of eq. (K1) in its ``sigma`` field (None: no σ).  The kind supplies
    ``sigma_coordinates(wi, wr)`` -> (φ, γ, d_slice) and ``sigma_scales``."""

    @property
    def has_sigma(self) -> bool:
        """True when the file holds the σ summary."""
        return self.sigma is not None

    def predict_sigma(self, wi, wr):
        """``(f, σ, σ_ln f)`` of eq. (K1) (:func:`predict_kes_sigma`), or None without the
        σ summary."""
        return None if self.sigma is None else predict_kes_sigma(self, wi, wr)
