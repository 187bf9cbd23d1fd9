r"""From a model to a BRDF f_r(wi, wr) (paper eq. 3–4, docs/method.md, "From the table to a BRDF"): the public front end.

:func:`evaluate` works for every model kind (:mod:`kesbrdf.models.base`): it asks the
model, which checks the mapping it was given against the ones its kind supports and
evaluates through :func:`kesbrdf.models.mappings.evaluate_pairs`.  For the ``kes`` kind (the default is the mapping the model records, ``parameters["mapping"]``:
``halfvector`` for new fits, ``deviation`` for files that record none):

``halfvector``
    γ = 2 θ_h and φ = φ_h of the half vector (Ward- and microfacet-like; a fibre's
    highlight, where h ⟂ t, is a function of h too).
``deviation``
    γ = angle between wr and the mirror image of wi, m = (−x, −y, z);
    φ = azimuth of (wi + wr) projected on the fabric plane.
``paper``
    Eq. 3–4 taken literally (see :func:`kesbrdf.models.mappings.paper_phi_gamma`).

For the first two,

.. math:: f_r(\omega_i, \omega_r) = c + \mathrm{fade}(\gamma)\,\frac{q(\phi, \gamma)}{w(\theta_i, \theta_r)}

with q read from the table by bilinear interpolation (periodic in φ, γ clamped to the
measured range), w the foreshortening weight (paper eq. 3's √(cos θ_i cos θ_r), bounded
toward grazing angles: :func:`kesbrdf.models.mappings.foreshortening`) and fade = 1 up to the
last measured γ, then to 0 over 6° (:func:`kesbrdf.models.mappings.fade`); models written
before the grazing-energy fix use √(cos θ_i cos θ_r) and hold the last column
(docs/decisions.md, "Grazing energy").  Both are reciprocal by construction and return every in-plane
input sample exactly.  The ``kes-halfdiff`` kind has the one mapping ``halfdiff``.

Edges (:mod:`kesbrdf.models.mappings`): directions are normalised here (any non-zero
length); a pair at or below the horizon — cos θ ≤ :data:`COS_EPS` = 1e-6 for either
direction, so θ = 90° exactly — gives 0; a non-finite component gives NaN; finite
input never gives inf or NaN.  Large inputs are evaluated in chunks.

The direction mappings themselves live in :mod:`kesbrdf.models.mappings` and the table
lookup in :mod:`kesbrdf.models.table`; both are re-exported here for backward compatibility.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.models.mappings import (
    AZIMUTH_EPS,
    COS_EPS,
    MAPPINGS,
    PAPER_MIN_SIN_BETA,
    paper_phi_gamma,
    to_phi_gamma,
    validate_mapping,
)
from kesbrdf.models.table import lookup

__all__ = [
    "MAPPINGS",
    "validate_mapping",
    "to_phi_gamma",
    "paper_phi_gamma",
    "lookup",
    "evaluate",
    "PAPER_MIN_SIN_BETA",
    "AZIMUTH_EPS",
    "COS_EPS",
]


def evaluate(model, wi, wr, mapping: str | None = None) -> np.ndarray:
    """f_r(wi, wr) of a model of any kind in 1/sr, shape broadcast(wi, wr)[:-1] + (C,).

    Parameters
    ----------
    model : kesbrdf.models.base.ReflectanceModel
    wi, wr : array_like, shape (..., 3)
        Directions toward the light and the viewer, fabric frame; normalised here.
    mapping : str, optional
        One of ``model.mappings``; default the model's ``default_mapping`` (for ``kes`` the
        mapping it records: ``halfvector`` for new fits, ``deviation`` for older files).
        A mapping the kind does not support is a one-line
        :class:`~kesbrdf.errors.ModelError`.

    >>> import numpy as np
    >>> from kesbrdf.measure.gonio import measure
    >>> from kesbrdf.models.kes import fit
    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> ref = AnisotropicWard(0.2, 0.2, rho_d=0.1, rho_s=0.05)
    >>> m = measure(ref)
    >>> model = fit(m)
    >>> bool(np.allclose(evaluate(model, m.wi, m.wr), m.values, rtol=1e-9))
    True
    >>> evaluate(model, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]).tolist()   # θ_r = 90°: at the horizon
    [0.0]
    """
    return model.evaluate(wi, wr, mapping)
