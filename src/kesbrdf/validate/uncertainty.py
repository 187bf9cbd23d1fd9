"""Per-prediction uncertainty of a model file, and its coverage of held-out truths.

A model says whether it carries a σ (``model.has_sigma``, the capability of
:mod:`kesbrdf.models.base`) and computes it (``model.predict_sigma``).  Today the
``fibre-prior`` kind does: its fit has a Laplace covariance, its file holds the
candidate models whose spread is the model term (the pure prior and the KES table
fitted to the same samples) and the support of the measured data, from which an
off-support term grows (:func:`kesbrdf.models.fibre_prior.predict_with_uncertainty`,
docs/prior.md §5).  ``fibre-coord`` (the dense default) inherits the same σ.  A ``kes``
model fitted since 2026-12-03 carries the σ of eq. (K1)
(:mod:`kesbrdf.models.kes_sigma`): the noise of its data, their own
leave-one-orientation-out interpolation error over ψ as a function of γ, and the
measured support, stored in its file (docs/decisions.md, "σ of kes models"); a
``kes-halfdiff`` model fitted since then the same form over every incidence line of its
dense data (:mod:`kesbrdf.models.halfdiff_sigma`, "σ of kes-halfdiff models").  A
baseline (nearest/linear) or a kes or kes-halfdiff file written before has no noise
estimate and no error estimate, so any σ computed from it alone would be invented:
asking for one is a :class:`~kesbrdf.errors.ModelError` that says so.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import ModelError

__all__ = ["has_uncertainty", "predict_sigma", "coverage", "COVERAGE_BANDS", "within_bands"]

#: The coverage a calibrated σ must give on held-out truths (issue 20): within 1σ
#: 60–76 % and within 2σ 90–98 % (a Gaussian gives 68.3 % and 95.4 %).
COVERAGE_BANDS = ((0.60, 0.76), (0.90, 0.98))


def has_uncertainty(model) -> bool:
    """True when ``model`` carries a per-prediction σ (``model.has_sigma``)."""
    return bool(getattr(model, "has_sigma", False))


def predict_sigma(model, wi, wr, source: str = "model"):
    r"""f_r and its σ at direction pairs (``model.predict_sigma``).

    For a ``kes`` model with its σ summary, eq. (K1) of :mod:`kesbrdf.models.kes_sigma`:
    σ² = n² + (a s(γ)^q d_φ)² + ((b₀ + b₁ s̄) d_slice)²; for a ``kes-halfdiff`` model the
    same with its own coordinates and scales (:mod:`kesbrdf.models.halfdiff_sigma`).

    For the ``fibre-prior`` kind, σ of ln f combines the fit noise propagated through the
    Laplace covariance, the spread between the candidates (the model, its pure prior and
    the stored KES table) and the off-support terms (between the measured orientations
    and off the measured slice), eq. (U1) of
    :func:`kesbrdf.models.fibre_prior.predict_with_uncertainty` (docs/prior.md §5):

    .. math:: \sigma_{\ln f}^2 = g^\top\Sigma_\theta g + \tfrac1K\sum_k(\ln f_k-\ln f)^2
              + (c_\psi s^q d_\psi)^2 + ((c_0 + c_1 s)\,d_\text{slice})^2

    with s the fabric's own misfit to the prior on the measured slice.

    Parameters
    ----------
    model : ReflectanceModel
    wi, wr : array_like (N, 3)
        Unit directions to the light and to the viewer (fabric frame).
    source : str
        Where the model came from, for the error message.

    Returns
    -------
    f, sigma, sigma_log : ndarray (N, C)
        Prediction (1/sr), σ in 1/sr (f·σ_ln f) and σ of ln f.

    Raises
    ------
    ModelError
        When the model carries no σ.
    """
    result = model.predict_sigma(wi, wr) if has_uncertainty(model) else None
    if result is None:
        raise ModelError(
            f"{source}: this {model.kind!r} model carries no uncertainty: it holds no noise or interpolation-error "
            "estimate (a kes or kes-halfdiff table written before 2026-12-03, one built with --interpolation other "
            "than kes, or a baseline); refit it with kesbrdf fit (default interpolation) or --kind fibre-prior"
        )
    return result


def coverage(pred, sigma_log, truth) -> dict:
    r"""Fraction of truths within 1σ and 2σ of the prediction, in log space.

    z = |ln(t + ε) − ln(p + ε)| / σ_ln f with ε = 10⁻⁴·max t (the same floor as
    :func:`kesbrdf.models.fibre_prior.calibration`).  A calibrated Gaussian σ gives 0.68 and
    0.95.

    Returns ``{"within_1sigma", "within_2sigma", "median_sigma_log", "n"}``.
    """
    p = np.asarray(pred, float)
    t = np.asarray(truth, float).reshape(p.shape)
    sl = np.asarray(sigma_log, float).reshape(p.shape)
    eps = max(float(np.max(t)), 1e-300) * 1e-4
    z = np.abs(np.log(np.maximum(t, 0) + eps) - np.log(np.maximum(p, 0) + eps)) / np.maximum(sl, 1e-12)
    return {"within_1sigma": float(np.mean(z <= 1)), "within_2sigma": float(np.mean(z <= 2)),
            "median_sigma_log": float(np.median(sl)), "n": int(z.size)}


def within_bands(within_1sigma: float, within_2sigma: float, tol: float = 0.0, bands=COVERAGE_BANDS) -> bool:
    """True when the two coverage fractions lie in :data:`COVERAGE_BANDS`, each band
    widened by ``tol`` on both sides (the finite-sample slack of the caller)."""
    (lo1, hi1), (lo2, hi2) = bands
    return lo1 - tol <= within_1sigma <= hi1 + tol and lo2 - tol <= within_2sigma <= hi2 + tol
