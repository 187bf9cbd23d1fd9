r"""The body term: one rule for every kind that fits one (docs/models.md, "The body term").

Every kind splits the reflectance into a Lambertian body and a non-negative lobe,

.. math:: f_r(\omega_i, \omega_r) = c + \text{lobe}(\omega_i, \omega_r), \qquad \text{lobe} \ge 0,

(``kes`` and ``kes-halfdiff``: c, the table holds the lobe; ``fibre-prior``: k_d of the
woven-cloth prior, docs/prior.md; ``fibre-coord``: k_d e^{δ₀} of eq. C1).  Since the lobe
is never negative, f_r ≥ c at every pair, and so at every measured sample:

.. math:: c \le c_\max = \max\bigl(0, \min_n y_n\bigr)  \qquad \text{(per channel)}   \qquad (B1)

The darkest reading is what the data supports for the body; anything above it is a
floor the data contradict.  Readings are noisy, so a body *fitted* jointly with the lobe
is held to

.. math:: c \le \max\bigl(0, \min_n (y_n + z\,\sigma_n)\bigr), \qquad z = 2     \qquad (B2)

with σ_n the reading's standard deviation (the measurement's uncertainty).  The rule:

* ``kes``, ``kes-halfdiff`` and the tabulated view of any kind (``body="auto"``) take
  c = c_max of (B1) (:func:`body_value`): the lobe carries everything above the darkest
  reading;
* ``fibre-coord``: when the free base prior's k_d exceeds (B2), the prior is fitted again
  with k_d held within it (:func:`log_body_upper`,
  ``kesbrdf.models.fibre_physics.fit_prior(bound_body=True)``), the corrections are
  fitted on both, and the bounded candidate is kept when it reproduces the readings
  clearly better (``kesbrdf.models.fibre_coord.BODY_KEEP_RATIO``).  On the dense Sadeghi
  black satin the free k_d was 0.039 1/sr against a darkest reading of 0.006 and the
  reference's own body of 0.0054: a floor that rendered the black satin grey and that
  the corrections could not take back;
* ``fibre-prior`` and the scattered fit fit c jointly with their lobe, free.  The darkest
  reading is usually at grazing view or light, where a real fabric's volume scattering
  falls below a Lambertian's, and their lobes cannot carry a floor: held to (B2) they
  predicted held-out data worse (docs/decisions.md, "The body term").

Noise moves the darkest reading down by about its σ, so (B1) slightly underestimates a
true Lambertian floor; that only moves energy to the lobe (which then reproduces the
samples).  A reading at or below 0 (a noise floor) gives c_max = 0.
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import KESError

__all__ = ["body_bound", "body_value", "log_body_upper", "LOG_BODY_MIN", "BODY_NOISE_Z"]

#: Readings' standard deviations a fitted body may exceed the darkest reading by (eq. B2):
#: with 116–900 readings the darkest one lies about 2–3 σ below its expectation, so
#: z = 2 keeps a true Lambertian floor inside the bound at the 2 % noise of the
#: reference benchmarks and the 5 % of the scattered fit's synthetic test.
BODY_NOISE_Z = 2.0
#: Smallest ln k_d of the parametric fits (a body of e⁻⁴⁰ ≈ 4·10⁻¹⁸ 1/sr is none).
LOG_BODY_MIN = -40.0


def body_bound(values, sigma=None, z: float = BODY_NOISE_Z) -> np.ndarray:
    """c_max of eq. (B1) per channel over ``values`` (N, C), ignoring NaN.

    Without ``sigma``: max(0, min y), the darkest reading (what ``body="auto"`` of the KES
    tables takes as the body).  With ``sigma`` (N, C), the readings' standard deviations:
    max(0, min (y + z σ)), the bound a fitted body must respect when the darkest reading
    may lie up to z σ below the truth (eq. B2).
    """
    v = np.asarray(values, float)
    v = v.reshape(v.shape[0], -1)
    if sigma is not None:
        v = v + z * np.abs(np.asarray(sigma, float).reshape(v.shape))
    return np.maximum(np.nanmin(v, axis=0), 0.0)


def body_value(body, values, n_channels: int):
    """(c (C,), mode) of a KES-table fit's ``body`` option.

    ``"auto"``: c = c_max (eq. B1) of ``values``; ``"none"``: c = 0 (the paper's pure
    lobe); a number or one per channel: that value.  Anything else raises
    :class:`~kesbrdf.errors.KESError`.
    """
    if isinstance(body, str) and body == "auto":
        return body_bound(values), "auto"
    if isinstance(body, str) and body == "none":
        return np.zeros(n_channels), "none"
    try:
        c = np.broadcast_to(np.asarray(body, float), (n_channels,)).copy()
    except ValueError:
        raise KESError(f"expected body 'auto', 'none' or a number per channel, got {body!r}") from None
    return c, "value"


def log_body_upper(values, sigma=None) -> np.ndarray:
    """Upper bound of ln k_d per channel for a parametric fit: ln c_max (eq. B1/B2), and
    just above :data:`LOG_BODY_MIN` where c_max is 0 (no body)."""
    c = body_bound(values, sigma)
    with np.errstate(divide="ignore"):
        lc = np.log(np.maximum(c, 0.0))
    return np.maximum(lc, LOG_BODY_MIN + 1e-6)

