r"""Direction mappings: from a pair (wi, wr) to the coordinates a model table is read at.

One module below every model kind (docs/method.md, "From the table to a BRDF"; docs/architecture.md, "Layers"), so that the kinds, the BRDF front
end and the consumers share the same definitions and nothing imports another module's
private helpers.

Mappings
--------
``deviation``
    γ = angle between wr and the mirror image of wi, m = (−x, −y, z); φ = azimuth of
    (wi + wr) projected on the fabric plane (Fig. 5 read literally).
``halfvector``
    γ = 2 θ_h and φ = φ_h of the half vector (Ward- and microfacet-like).
``paper``
    Eq. 3–4 taken literally (:func:`paper_phi_gamma`).
``halfdiff``
    (φ_h, θ_h, θ_d): half-vector azimuth, half angle and difference angle
    (:func:`to_half_diff`), used by the ``kes-halfdiff`` kind.

Foreshortening normalisation
----------------------------
Every tabulated kind stores a lobe quantity q = (f_r − c)·w and evaluates
f_r = c + q/w, with w the *foreshortening weight* of the pair (:func:`foreshortening`):

``bounded`` (default of new fits)
    w = max(√(cos θ_i cos θ_r), λ·max(cos θ_i, cos θ_r)), λ = :data:`BOUNDED_LAMBDA`.
``sqrtcos``
    w = √(cos θ_i cos θ_r), paper eq. 3 read literally (files written before the
    bounded form, and the ``paper`` mapping).

Eq. 3's 1/√(cos θ_i cos θ_r) lets a lobe's directional albedo grow as
1/√cos θ_i toward grazing incidence (3× at 89.99° on a Ward fit, docs/decisions.md).
The bounded form equals it wherever the two cosines are within a factor 1/λ² = 4 of
each other and is the Ashikhmin–Shirley/Neumann 1/max(cos θ_i, cos θ_r) (over λ)
elsewhere, so (f_r − c) cos θ_r ≤ q/λ and the albedo is at most πc + (1/λ)∫q dω_r at
every incidence.  It is symmetric in (θ_i, θ_r): reciprocity is kept.

Where wi + wr has no component in the fabric plane (the mirror direction for
``deviation``, h ∥ z for the half-vector mappings), φ is the azimuth of the plane of
incidence, (wr − wi) projected (docs/method.md, "From the table to a BRDF").

Directions at the public API
----------------------------
:func:`evaluate_pairs` is the one front end every kind's ``evaluate`` goes through:

* inputs are broadcast, shape (..., 3); any length > 0 is accepted and normalised
  (after scaling by the largest component, so 1e300 and 1e-300 lengths are fine);
* a pair with a non-finite component gives NaN (every channel);
* a pair with a zero vector, or with cos θ ≤ :data:`COS_EPS` for either direction,
  is *at or below the horizon* and gives exactly 0 (so θ = 90°, whose cosine is
  6e-17 in floating point, gives 0, and f_r ≤ q / COS_EPS stays bounded);
* the kind's core is called on the remaining pairs only, in chunks of
  :data:`EVAL_CHUNK` pairs, so the peak memory is the output plus a few chunk-sized
  temporaries (and one copy of the inputs when they must be broadcast).
"""

from __future__ import annotations

import math

import numpy as np

from kesbrdf.errors import KesbrdfError

__all__ = [
    "MAPPINGS",
    "TABLE_MAPPINGS",
    "FIT_MAPPING",
    "HALFDIFF",
    "NORMALISATIONS",
    "BOUNDED_LAMBDA",
    "EXTRAPOLATIONS",
    "FADE_DEG",
    "fade",
    "foreshortening",
    "line_foreshortening",
    "AZIMUTH_EPS",
    "PAPER_MIN_SIN_BETA",
    "COS_EPS",
    "EVAL_CHUNK",
    "validate_mapping",
    "azimuth",
    "to_phi_gamma",
    "paper_phi_gamma",
    "in_plane_half_diff",
    "to_half_diff",
    "unit_rows",
    "evaluate_pairs",
]

#: Mappings of the ``kes`` table (first = the default of files that record none).
MAPPINGS = ("deviation", "halfvector", "paper")
#: The mappings a table can be fitted for and rendered with (``paper`` is eq. 3–4 as
#: printed: an evaluation only, singular and not reciprocal).
TABLE_MAPPINGS = ("deviation", "halfvector")
#: The mapping new ``kes`` fits record (``parameters["mapping"]``) and are evaluated
#: with unless told otherwise: the half vector's azimuth and 2θ_h, which is where a
#: microfacet lobe and a fibre's highlight (h ⟂ t) live (docs/decisions.md, "The half-vector
#: mapping is the default of new fits").  Files that record no mapping are ``deviation``.
FIT_MAPPING = "halfvector"
#: The mapping of the ``kes-halfdiff`` kind.
HALFDIFF = "halfdiff"

#: Foreshortening normalisations (module docstring; first = default of new fits).
NORMALISATIONS = ("bounded", "sqrtcos")
#: λ of the ``bounded`` normalisation: the paper's √(cos θ_i cos θ_r) is kept while
#: min/max of the two cosines is at least λ² = 1/4 (on the paper's line θ_i + θ_r = 90°
#: up to |γ| ≈ 62°, θ_r ≈ 76°); beyond, the lobe's projected value f_r cos θ is held
#: below q/λ, so the grazing albedo can reach at most ~2× the lobe's ∫q dω
#: (docs/decisions.md, "Grazing energy").
BOUNDED_LAMBDA = 0.5
#: What a table's lobe does beyond its last deviation (γ_max, or θ_h,max of the
#: ``kes-halfdiff`` kind), ``parameters["extrapolation"]``: ``fade`` (new fits) scales it
#: by max(0, 1 − (γ − γ_max)/FADE_DEG), ``hold`` (files written before) keeps the last
#: column up to γ = π.  Held, the in-plane grazing value (θ_i = 3°, θ_r = 87° in the
#: paper protocol) lands on every back-scattering pair, whose solid angle grows toward
#: grazing incidence: it alone lifts the grazing albedo of a bright fabric above 1
#: (docs/decisions.md, "Grazing energy").
EXTRAPOLATIONS = ("fade", "hold")
#: Width of the ``fade``, degrees of γ (one deviation step of the paper's protocol).
FADE_DEG = 6.0

#: Projected lengths below this count as zero when taking an azimuth.
AZIMUTH_EPS = 1e-12
#: eq. 3 divides by sin β; it is clamped here (the printed equation is singular).
PAPER_MIN_SIN_BETA = 1e-6
#: "At or below the horizon": cos θ ≤ COS_EPS for wi or wr (θ ≳ 89.99994°).  Such pairs
#: give 0, and every f_r = c + q/√(cos θ_i cos θ_r) stays below c + q/COS_EPS.
COS_EPS = 1e-6
#: Pairs per chunk in :func:`evaluate_pairs`: small enough that a chunk's temporaries
#: stay in cache, large enough to amortise numpy's per-call overhead.
EVAL_CHUNK = 1 << 14

_TWO_PI = 2.0 * math.pi
_AZ_EPS2 = AZIMUTH_EPS * AZIMUTH_EPS


def validate_mapping(mapping: str, valid=MAPPINGS) -> str:
    """Return ``mapping`` if it is one of ``valid``, else raise with the valid names."""
    if mapping not in valid:
        raise KesbrdfError(f"unknown mapping {mapping!r}; expected one of {', '.join(valid)}")
    return mapping


def azimuth(x, y, fallback_x, fallback_y) -> np.ndarray:
    """Azimuth in [0, 2π) of (x, y), or of the fallback where |(x, y)| < AZIMUTH_EPS."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    small = x * x + y * y < _AZ_EPS2
    if np.any(small):
        x = np.where(small, fallback_x, x)
        y = np.where(small, fallback_y, y)
    phi = np.arctan2(y, x)
    return np.where(phi < 0.0, phi + _TWO_PI, phi)


def _deviation(wi, wr):
    """(φ, γ) of the deviation mapping, arrays (n,) from (n, 3) rows; no np.cross/hypot/mod."""
    ix, iy, iz = wi[..., 0], wi[..., 1], wi[..., 2]
    rx, ry, rz = wr[..., 0], wr[..., 1], wr[..., 2]
    # |wr × m| and wr·m with m = (−ix, −iy, iz)
    cx = ry * iz + rz * iy
    cy = -rz * ix - rx * iz
    cz = ry * ix - rx * iy
    gamma = np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), rz * iz - rx * ix - ry * iy)
    phi = azimuth(ix + rx, iy + ry, rx - ix, ry - iy)
    return phi, gamma


def _halfvector(wi, wr):
    hx = wi[..., 0] + wr[..., 0]
    hy = wi[..., 1] + wr[..., 1]
    hz = wi[..., 2] + wr[..., 2]
    gamma = 2.0 * np.arctan2(np.sqrt(hx * hx + hy * hy), hz)
    phi = azimuth(hx, hy, wr[..., 0] - wi[..., 0], wr[..., 1] - wi[..., 1])
    return phi, gamma


def to_phi_gamma(wi, wr, mapping: str = "deviation"):
    """(φ, γ) of direction pairs for the ``deviation`` or ``halfvector`` mapping.

    Parameters
    ----------
    wi, wr : array_like, shape (..., 3)
        Unit vectors toward the light and the viewer, fabric frame.

    Returns
    -------
    phi : ndarray
        Deviation azimuth in [0, 2π).
    gamma : ndarray
        Deviation from the mirror direction, [0, π].

    >>> wi = np.array([-np.sin(0.5), 0, np.cos(0.5)]); wr = np.array([np.sin(0.7), 0, np.cos(0.7)])
    >>> [round(float(v), 12) for v in to_phi_gamma(wi, wr)]
    [0.0, 0.2]
    """
    wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
    if mapping == "deviation":
        return _deviation(wi, wr)
    if mapping == "halfvector":
        return _halfvector(wi, wr)
    raise KesbrdfError(f"to_phi_gamma: expected mapping 'deviation' or 'halfvector', got {mapping!r}")


def paper_phi_gamma(theta_i, phi_i, theta_r, phi_r):
    r"""Eq. 3–4 read literally: (φ, signed γ) and sin β.

    .. math::

        \phi = \frac{\pi}{2} - (\phi_i + \phi_r),\quad \gamma = \theta_r - \theta_i,\quad
        \sin\frac{\beta}{2} = \frac12\sqrt{\sin^2(\phi_r - \phi_i - \pi) + \cos^2\theta_r}
        \tag{3–4}

    Kept to reproduce the paper, not recommended: the printed formula is not
    reciprocal (θ_r and θ_i enter eq. 4 differently), is singular where sin β → 0
    (sin β is clamped at :data:`PAPER_MIN_SIN_BETA`) and at grazing angles
    (cos θ → 0), and its φ depends on the sum of the azimuths, so the highlight it
    predicts is not a lobe around the mirror direction once the fabric is rotated.
    Signed γ < 0 reads the table at azimuth φ + π (docs/method.md, "From the table to a BRDF").
    """
    phi = np.mod(np.pi / 2 - (phi_i + phi_r), 2 * np.pi)
    gamma = theta_r - theta_i
    half = 0.5 * np.sqrt(np.sin(phi_r - phi_i - np.pi) ** 2 + np.cos(theta_r) ** 2)
    beta = 2.0 * np.arcsin(np.clip(half, 0.0, 1.0))
    return phi, gamma, np.maximum(np.sin(beta), PAPER_MIN_SIN_BETA)


def foreshortening(cos_i, cos_r, normalisation: str = "bounded") -> np.ndarray:
    r"""Foreshortening weight w of f_r = c + q/w (module docstring), ≥ 0.

    .. math:: w = \max\bigl(\sqrt{\cos\theta_i\cos\theta_r},\;
              \lambda\max(\cos\theta_i, \cos\theta_r)\bigr)

    (``bounded``), or √(cos θ_i cos θ_r) (``sqrtcos``); cosines below 0 count as 0.

    >>> float(foreshortening(0.5, 0.5)), float(foreshortening(1e-4, 1.0)), float(foreshortening(1e-4, 1.0, "sqrtcos"))
    (0.5, 0.5, 0.01)
    """
    ci = np.maximum(np.asarray(cos_i, float), 0.0)
    cr = np.maximum(np.asarray(cos_r, float), 0.0)
    g = np.sqrt(ci * cr)
    if normalisation == "sqrtcos":
        return g
    if normalisation != "bounded":
        raise KesbrdfError(f"unknown normalisation {normalisation!r}; expected one of {', '.join(NORMALISATIONS)}")
    return np.maximum(g, BOUNDED_LAMBDA * np.maximum(ci, cr))


def fade(gamma, gamma_max: float, extrapolation: str = "fade") -> np.ndarray:
    """Factor of the lobe beyond the table's last deviation (:data:`EXTRAPOLATIONS`):
    1 up to ``gamma_max``, then linear to 0 over :data:`FADE_DEG` (``fade``); 1 (``hold``).

    >>> [round(float(v), 12) for v in fade(np.radians([80.0, 87.0, 90.0]), np.radians(84.0))]
    [1.0, 0.5, 0.0]
    """
    gamma = np.asarray(gamma, float)
    if extrapolation == "hold":
        return np.ones_like(gamma)
    if extrapolation != "fade":
        raise KesbrdfError(f"unknown extrapolation {extrapolation!r}; expected one of {', '.join(EXTRAPOLATIONS)}")
    return np.clip(1.0 - (gamma - gamma_max) * (1.0 / math.radians(FADE_DEG)), 0.0, 1.0)


def line_foreshortening(gamma, line_sum: float, normalisation: str = "bounded") -> np.ndarray:
    """:func:`foreshortening` on the in-plane line θ_i + θ_r = S at deviation |γ|.

    There θ_{i,r} = (S ∓ |γ|)/2, so cos θ_i cos θ_r = (cos γ + cos S)/2 and the larger
    cosine is cos((S − |γ|)/2).

    >>> [round(float(w), 6) for w in line_foreshortening(np.radians([0.0, 84.0]), np.pi / 2)]
    [0.707107, 0.499315]
    """
    gamma = np.abs(np.asarray(gamma, float))
    g = np.sqrt(np.clip((np.cos(gamma) + math.cos(line_sum)) / 2.0, 0.0, None))
    if normalisation == "sqrtcos":
        return g
    if normalisation != "bounded":
        raise KesbrdfError(f"unknown normalisation {normalisation!r}; expected one of {', '.join(NORMALISATIONS)}")
    cos_hi = np.cos(np.clip((line_sum - gamma) / 2.0, 0.0, np.pi / 2))
    return np.maximum(g, BOUNDED_LAMBDA * cos_hi)


def in_plane_half_diff(theta_i, theta_r):
    r"""(θ_h, θ_d, upper) of in-plane pairs: θ_h = |θ_r − θ_i|/2, θ_d = (θ_i + θ_r)/2.

    ``upper`` is true where θ_r ≥ θ_i (half vector at azimuth ψ).

    >>> [round(float(np.degrees(v)), 9) for v in in_plane_half_diff(np.radians(12.0), np.radians(30.0))[:2]]
    [9.0, 21.0]
    """
    theta_i = np.asarray(theta_i, float)
    theta_r = np.asarray(theta_r, float)
    return np.abs(theta_r - theta_i) / 2.0, (theta_i + theta_r) / 2.0, theta_r >= theta_i


def to_half_diff(wi, wr):
    """(φ_h, θ_h, θ_d) of direction pairs, radians.

    Parameters
    ----------
    wi, wr : array_like, shape (..., 3)
        Unit vectors toward the light and the viewer.

    Returns
    -------
    phi_h : ndarray
        Half-vector azimuth in [0, 2π); the plane of incidence where h ∥ z.
    theta_h : ndarray
        Angle between h and the normal, [0, π/2) above the horizon.
    theta_d : ndarray
        Angle between wi (or wr) and h, [0, π/2]: half the angle between wi and wr.

    Every expression is symmetric in (wi, wr) bit for bit (except φ_h at h ∥ z).

    >>> wi = np.array([-np.sin(0.2), 0, np.cos(0.2)]); wr = np.array([np.sin(0.6), 0, np.cos(0.6)])
    >>> [round(float(v), 12) for v in to_half_diff(wi, wr)]
    [0.0, 0.2, 0.4]
    """
    wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
    ix, iy, iz = wi[..., 0], wi[..., 1], wi[..., 2]
    rx, ry, rz = wr[..., 0], wr[..., 1], wr[..., 2]
    hx, hy, hz = ix + rx, iy + ry, iz + rz
    phi_h = azimuth(hx, hy, rx - ix, ry - iy)
    theta_h = np.arctan2(np.sqrt(hx * hx + hy * hy), hz)
    cx = iy * rz - iz * ry
    cy = iz * rx - ix * rz
    cz = ix * ry - iy * rx
    theta_d = 0.5 * np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), ix * rx + iy * ry + iz * rz)
    return phi_h, theta_h, theta_d


def unit_rows(v: np.ndarray):
    """(v / |v|, ok) for rows of ``v`` (n, 3); ``ok`` is false for zero or non-finite rows.

    Rows whose squared length under- or overflows are scaled by their largest
    component first, so any finite non-zero vector is normalised correctly.
    """
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        n2 = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]
    plain = (n2 > 1e-280) & (n2 < 1e280)
    if plain.all():
        return v / np.sqrt(n2)[:, None], plain
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        scale = np.max(np.abs(v), axis=1)
        ok = np.isfinite(scale) & (scale > 0)
        w = v / np.where(ok, scale, 1.0)[:, None]
        n = np.sqrt(np.sum(w * w, axis=1))
        return w / np.where(ok, n, 1.0)[:, None], ok


def evaluate_pairs(core, wi, wr, n_channels: int, mapping: str, chunk: int = EVAL_CHUNK) -> np.ndarray:
    """Run a kind's core ``core(wi, wr, mapping) -> (n, C)`` on clean pairs (module docstring).

    ``core`` receives unit rows (n, 3), all with cos θ > :data:`COS_EPS`, and returns
    f_r in 1/sr; this front end supplies the zeros (horizon) and NaNs (non-finite in).
    Returns shape broadcast(wi, wr)[:-1] + (C,).
    """
    wi = np.asarray(wi, float)
    wr = np.asarray(wr, float)
    if wi.ndim < 1 or wr.ndim < 1 or wi.shape[-1] != 3 or wr.shape[-1] != 3:
        raise KesbrdfError(f"expected directions of shape (..., 3), got {wi.shape} and {wr.shape}")
    try:
        shape = np.broadcast_shapes(wi.shape, wr.shape)
    except ValueError:
        raise KesbrdfError(f"expected broadcastable directions, got shapes {wi.shape} and {wr.shape}") from None
    wi = np.broadcast_to(wi, shape).reshape(-1, 3)
    wr = np.broadcast_to(wr, shape).reshape(-1, 3)
    n = wi.shape[0]
    out = np.empty((n, n_channels))
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        a, ok_a = unit_rows(wi[start:stop])
        b, ok_b = unit_rows(wr[start:stop])
        above = ok_a & ok_b & (a[:, 2] > COS_EPS) & (b[:, 2] > COS_EPS)
        o = out[start:stop]
        if above.all():
            o[...] = core(a, b, mapping)
            continue
        o.fill(0.0)
        finite = np.isfinite(wi[start:stop]).all(axis=1) & np.isfinite(wr[start:stop]).all(axis=1)
        o[~finite] = np.nan
        idx = np.flatnonzero(above)
        if idx.size:
            o[idx] = core(a[idx], b[idx], mapping)
    return out.reshape(shape[:-1] + (n_channels,))
