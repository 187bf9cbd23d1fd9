r"""The extended KES interpolation over orientation (paper eq. 1–2, docs/method.md, "Interpolation over orientation").

KES treats a fabric as an orthotropic sheet.  Write :math:`K(\psi) = 1/\rho(\psi, \gamma)`
for a fixed deviation γ.  Sakaguchi's extension interpolates K between the warp (0),
bias (π/4) and weft (π/2) like the directional compliance of an orthotropic plate:

.. math::

    K(\phi) = K_0\cos^4\phi + G'\sin^2\phi\cos^2\phi + K_{90}\sin^4\phi,
    \qquad G' = 4K_{45} - K_0 - K_{90}                      \tag{1–2}

With the other bias π3/4 measured as well, the lowest-order term that breaks the
φ → π − φ symmetry gives the 4-orientation form (docs/method.md, "Interpolation over orientation")

.. math::

    K(\phi) = K_0 c^4 + B c^2 s^2 + K_{90} s^4 + D c s,\quad
    B = 2(K_{45}+K_{135}) - K_0 - K_{90},\quad D = K_{45} - K_{135}.

On the whole circle of deviation azimuths (docs/method.md, "From the table to a BRDF") the eight half-samples at
k·π/4 are interpolated by an even part (the average of the two halves, exactly the
form above: span {1, cos 2φ, sin 2φ, cos 4φ}) plus an odd part (half their
difference, span {cos φ, sin φ, cos 3φ, sin 3φ}).  With three orientations the even
span is {1, cos 2φ, cos 4φ} (eq. 1–2) and the odd span {cos φ, sin φ, cos 3φ}.

Both are linear in K, so they are written here as a basis matrix: ``coefficients =
K_half @ inverse(basis(half_azimuths)).T`` and ``K(φ) = coefficients @ basis(φ).T``.
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import KESError

__all__ = [
    "kes3",
    "kes4",
    "HALF_AZIMUTHS",
    "half_slots",
    "circle_basis",
    "interpolate_circle",
    "interpolate_circle_log",
]

#: Azimuths of the eight half-samples: ψ = 0, 45, 90, 135° (+γ halves) then
#: ψ + 180° (−γ halves), radians.
HALF_AZIMUTHS = np.radians(np.arange(8) * 45.0)


def kes3(K0, K45, K90, phi):
    r"""Paper eq. 1–2: :math:`K(\phi)` from warp, π/4-bias and weft values of K = 1/ρ.

    Parameters
    ----------
    K0, K45, K90 : array_like
        1/ρ at φ = 0, π/4, π/2; broadcast together with ``phi``.
    phi : array_like
        Orientation, radians (the paper measures it from the warp here; see
        ``kesbrdf.models.brdf`` for the paper's own wording).

    Returns
    -------
    ndarray
        K(φ).  ρ_KES = 1 / K(φ).

    >>> round(float(kes3(1.0, 2.0, 3.0, np.pi / 4)), 12)  # K(π/4) = K_45 (round-off: 1.9999999999999996)
    2.0
    """
    c2 = np.cos(phi) ** 2
    s2 = np.sin(phi) ** 2
    G_prime = 4.0 * np.asarray(K45) - K0 - K90
    return K0 * c2 * c2 + G_prime * s2 * c2 + K90 * s2 * s2


def kes4(K0, K45, K90, K135, phi):
    r"""The 4-orientation form (docs/method.md, "Interpolation over orientation"); equals :func:`kes3` when K45 = K135.

    .. math:: K = K_0 c^4 + B c^2 s^2 + K_{90} s^4 + D c s

    >>> float(kes4(1.0, 2.0, 3.0, 4.0, 3 * np.pi / 4))
    4.0
    """
    c = np.cos(phi)
    s = np.sin(phi)
    B = 2.0 * (np.asarray(K45) + K135) - K0 - K90
    D = np.asarray(K45) - K135
    return K0 * c**4 + B * c * c * s * s + K90 * s**4 + D * c * s


def half_slots(orientations: int) -> np.ndarray:
    """Indices into :data:`HALF_AZIMUTHS` used with 3 or 4 orientations."""
    if orientations == 4:
        return np.arange(8)
    if orientations == 3:
        return np.array([0, 1, 2, 4, 5, 6])
    raise KESError(f"expected orientations 3 or 4, got {orientations!r}")


def circle_basis(phi, orientations: int = 4) -> np.ndarray:
    """Basis functions of the whole-circle interpolation at ``phi``, shape (..., n).

    n = 8 for four orientations, 6 for three (module docstring).
    """
    phi = np.asarray(phi, float)
    if orientations == 4:
        funcs = [
            np.ones_like(phi), np.cos(2 * phi), np.sin(2 * phi), np.cos(4 * phi),
            np.cos(phi), np.sin(phi), np.cos(3 * phi), np.sin(3 * phi),
        ]
    elif orientations == 3:
        funcs = [
            np.ones_like(phi), np.cos(2 * phi), np.cos(4 * phi),
            np.cos(phi), np.sin(phi), np.cos(3 * phi),
        ]
    else:
        raise KESError(f"expected orientations 3 or 4, got {orientations!r}")
    return np.stack(funcs, axis=-1)


def _solve_matrix(orientations: int) -> np.ndarray:
    slots = half_slots(orientations)
    A = circle_basis(HALF_AZIMUTHS[slots], orientations)
    return np.linalg.inv(A)


def interpolate_circle(K_half, phi, orientations: int = 4) -> np.ndarray:
    """Interpolate K over the whole circle of deviation azimuths.

    Parameters
    ----------
    K_half : array_like, shape (..., 8)
        K = 1/q at the half-azimuths :data:`HALF_AZIMUTHS`; with three orientations
        the slots 3 and 7 (135°, 315°) are ignored.
    phi : array_like, shape (P,)
        Azimuths where K is wanted, radians.

    Returns
    -------
    ndarray, shape (..., P)
        K(φ).  Passes through every used half-sample exactly; its even part is
        :func:`kes4` (or :func:`kes3`).
    """
    K_half = np.asarray(K_half, float)
    slots = half_slots(orientations)
    coefficients = K_half[..., slots] @ _solve_matrix(orientations).T
    return coefficients @ circle_basis(np.asarray(phi, float), orientations).T


def interpolate_circle_log(q_half, phi, orientations: int = 4) -> np.ndarray:
    """Fallback (docs/method.md, "Interpolation over orientation"): the same interpolation applied to log q; returns q(φ) > 0.

    log q(φ) is held within the range of the used half-samples (per row and channel): the
    trigonometric interpolant overshoots between them, and in log space an overshoot is a
    factor.  The result still passes through every half-sample.
    """
    q_half = np.asarray(q_half, float)
    if np.any(q_half <= 0):
        raise KESError("log interpolation needs positive q at every half-sample")
    logs = np.log(q_half)
    used = logs[..., half_slots(orientations)]
    out = interpolate_circle(logs, phi, orientations)
    return np.exp(np.clip(out, used.min(axis=-1, keepdims=True), used.max(axis=-1, keepdims=True)))
