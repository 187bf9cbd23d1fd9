r"""KES over the half-vector azimuth for measurements with several incidence angles.

The ``"kes"`` model (:mod:`kesbrdf.models.kes`) uses one incidence line θ_i + θ_r = 90°,
so over the hemisphere it extrapolates by assumption (docs/method.md, "Several incidence angles").  When every
orientation was measured at many (θ_i, θ_r) pairs — ``kesbrdf.measure.gonio.measure(ref,
protocol="dense")`` — this module builds the ``"kes-halfdiff"`` model, which keeps
them all: for a pair (wi, wr) it takes the half vector's azimuth as φ, reads each
measured orientation's in-plane table at the in-plane pair with the same half and
difference angles (θ_h, θ_d), and applies KES over φ (docs/method.md, "Several incidence angles").

In-plane geometry
-----------------
At orientation ψ the light is at azimuth ψ + π and polar angle θ_i, the viewer at ψ
and θ_r.  The half vector h = normalize(wi + wr) then lies in the plane of incidence:

.. math::

    \phi_h = \begin{cases}\psi & \theta_r \ge \theta_i\\ \psi + \pi & \theta_r < \theta_i\end{cases},
    \qquad \theta_h = \frac{|\theta_r - \theta_i|}{2},
    \qquad \theta_d = \angle(\omega_i, h) = \frac{\theta_i + \theta_r}{2}.

Orientation k (ψ = k·π/4) therefore fills the half-azimuth slots k (θ_r ≥ θ_i) and
k + 4 (θ_r ≤ θ_i) of :data:`kesbrdf.models.interpolation.HALF_AZIMUTHS`; mirror samples (θ_i = θ_r)
go to both.  In-plane samples cover the triangle θ_h ≤ θ_d, θ_h + θ_d = max(θ_i, θ_r)
≤ θ_max.

How the table is filled
-----------------------
1. Body: ``body="auto"`` fits the Fresnel-like body c g(cos θ_i) g(cos θ_r) of eq. B3
   of :mod:`kesbrdf.models.body` and keeps it when the samples show one (eq. B5–B6);
   otherwise, and with ``body="lambertian"``, c = max(0, min f_r) per channel over the
   in-plane samples used (eq. B1, the rule every kind shares); ``"none"`` is c = 0, a
   number sets c.  The body is subtracted at each sample's own (θ_i, θ_r) and added back
   at each node's for the interpolation over φ (step 4), so off the plane it is read at the
   pair's own angles.
2. Normalisation (``normalisation="bounded"``, default): the table holds
   q = (f_r − c)·w with w the foreshortening weight of :func:`kesbrdf.models.mappings.foreshortening`,
   max(√(cos θ_i cos θ_r), λ·max(cos θ_i, cos θ_r)): the paper's eq. 3 quantity, as
   the ``"kes"`` kind uses, bounded toward grazing angles so that the directional albedo
   stays bounded at grazing incidence (docs/decisions.md, "Grazing energy").  In-plane,
   w is a function of (θ_h, θ_d) alone, so this changes nothing at the measured
   geometries; off the plane the evaluation divides by the pair's own w, which keeps a
   lobe's 1/w growth toward grazing angles, up to 1/λ.  ``"sqrtcos"`` is eq. 3's
   √(cos θ_i cos θ_r) unbounded (files written before ``bounded``, whose lobe albedo
   grows as 1/√cos θ_i at grazing incidence).
   ``"none"`` (w = 1) tabulates f_r − c itself, as read literally from the body-term split (docs/method.md, "The body term").
   Measured on the Fig. 6 hemispheres (light θ_i = 30°, φ_i = 90° and 45°, viewer to
   80°, dense 6° protocol): anisotropic Ward α = 0.15/0.3, RMSE 0.0012 ("sqrtcos")
   vs 0.0015 ("none"); Ashikhmin–Shirley n = 10/100, 0.037 vs 0.033 (measured before
   ``bounded``, which differs from ``sqrtcos`` only where one cosine is below 1/4 of
   the other).
3. Resampling per slot: the lobe part (f_r − c)·w of the slot's samples, scattered
   over (θ_h, θ_d), is interpolated linearly (Delaunay,
   ``scipy.interpolate.LinearNDInterpolator``) onto a regular grid with the data's
   natural step (3° for a 6° (θ_i, θ_r) grid, so that every sample is a grid node).
   θ_d is compressed by :data:`THETA_D_SCALE` before the triangulation: a lobe varies
   fast with θ_h and slowly with θ_d, and on the checkerboard the samples form in
   (θ_h, θ_d) the compressed metric makes the triangulation interpolate at constant
   θ_h.  Grid nodes outside the measured in-plane triangle keep θ_h and clamp θ_d into
   [θ_h, θ_max − θ_h]: nodes with θ_h > θ_d (light and viewer on the same side of the
   normal, never in-plane) read θ_i = 0, nodes past the last measured angle read
   max(θ_i, θ_r) = θ_max.  θ_h is kept because the lobe depends on it most; clamping
   θ_h down to θ_d instead puts the mirror peak on the retro-reflection direction
   (hemisphere RMSE 0.05–0.10 instead of 0.001–0.003 on Ward references).
   Gaps of scattered data outside the convex hull take the nearest sample.
4. Body back in: at every node the measured quantity Q = lobe + c·w(node) is formed;
   KES works on it, body included, exactly as :func:`kesbrdf.models.kes.fit` does.  (KES on
   the bare lobe K = 1/(f − c) blows up where the lobe is far below the body:
   hemisphere RMSE 0.22 instead of 0.0012 on Ward α = 0.15/0.3.)
5. Noise floor: Q is floored at ``noise_floor`` (default 1e-4 × the channel's peak Q,
   as :func:`kesbrdf.models.kes.fit`) so that K = 1/Q is finite; the floored node counts
   are recorded in ``diagnostics["floored"]``.
6. KES: for every (θ_h, θ_d) node the whole-circle interpolation of K = 1/Q over φ
   (:func:`kesbrdf.models.interpolation.interpolate_circle`, 3 or 4 orientations) fills a φ grid of
   ``n_phi`` cells.  Where K(φ) ≤ 0 somewhere, the default ``fallback="log"``
   interpolates log Q at that node instead, records the nodes in
   ``diagnostics["fallback"]`` and a one-line warning naming the θ_h affected in
   ``diagnostics["warnings"]``; ``fallback="error"`` raises
   :class:`~kesbrdf.errors.KESError`.
7. The body is split off again: ``table[φ, θ_h, θ_d, channel] = max(Q(φ) − c·w, 0)``.

With the paper's protocol (one line θ_i + θ_r = 90°) each slot's samples lie on the
line θ_d = 45°; the lobe is interpolated along it and held constant in θ_d (the body
weight still follows each node's geometry), close to the ``"kes"`` model read
through the ``halfvector`` mapping.

Evaluation
----------
For a pair (wi, wr) above the horizon: h = wi + wr; φ_h = azimuth of h (where h has
no in-plane component, the azimuth of wr − wi, the plane of incidence, as
:func:`kesbrdf.models.brdf.to_phi_gamma`); θ_h = angle(h, z); θ_d = angle(wi, h), computed
as half the angle between wi and wr; then

.. math:: f_r = c + \frac{T(\phi_h, \theta_h, \theta_d)}{w(\theta_i, \theta_r)}

(w of :func:`kesbrdf.models.mappings.foreshortening`, √(cos θ_i cos θ_r) away from grazing)
with T read by trilinear interpolation (φ periodic, θ_h and θ_d clamped to the grid;
beyond the last θ_h the lobe fades to 0 over :data:`kesbrdf.models.mappings.FADE_DEG` of
γ = 2θ_h, ``parameters["extrapolation"] = "fade"``; files without it hold the last θ_h).
(``normalisation="none"``: without the division).  Swapping wi and wr leaves h, θ_h
and θ_d unchanged, so the model is reciprocal by construction (at h ∥ z the swap
turns φ_h by π, and the table's θ_h = 0 row is π-periodic because both halves hold
the same mirror samples); every in-plane input sample sits on a grid
node and is returned exactly (up to round-off), floored samples and the normal pair
θ_i = θ_r = 0 excepted (the same geometry at every ψ: its samples are averaged).
Directions at or below the horizon give 0; NaN in gives NaN out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from typing import ClassVar

from kesbrdf.models import interpolation as kes
from kesbrdf._version import __version__
from kesbrdf.errors import KESError, KesbrdfError, MeasurementError, ModelError, where
from kesbrdf.models.base import ReflectanceModel, register, check_fit_options
from kesbrdf.models.body import BodyLaw, body_factor, body_term
from kesbrdf.models.halfdiff_sigma import HALFDIFF_SIGMA_SCALES, SUPPORT_KEYS, halfdiff_coordinates
from kesbrdf.models.halfdiff_sigma import sigma_summary as halfdiff_sigma_summary
from kesbrdf.models.kes_sigma import StoredSigma, check_summary
from kesbrdf.models.mappings import EXTRAPOLATIONS, HALFDIFF, fade, foreshortening, in_plane_half_diff, to_half_diff
from kesbrdf.measure.measurement import Measurement
from kesbrdf.models.kes import (
    FALLBACKS,
    ORIENTATION_TOL,
    RELATIVE_NOISE_FLOOR,
    fallback_warning,
    select_orientations,
)
from kesbrdf.models.table import check_uniform_grid, check_values

__all__ = [
    "KIND",
    "NORMALISATIONS",
    "HalfDiffModel",
    "fit_halfdiff",
    "table_coverage",
    "MIN_TABLE_COVERAGE",
    "evaluate_halfdiff",
    "in_plane_half_diff",
    "to_half_diff",
    "lookup_halfdiff",
    "mirror_behaviour",
    "to_dict",
    "from_dict",
]

#: ``kind`` of the model file (docs/formats.md).
KIND = "kes-halfdiff"
#: What the table holds: ``"bounded"`` q = (f − c)·w (default; w of
#: :func:`kesbrdf.models.mappings.foreshortening`), ``"sqrtcos"`` q = (f − c)·√(cos θ_i cos θ_r)
#: (paper eq. 3 unbounded; files without the parameter), ``"none"`` the lobe f − c itself.
NORMALISATIONS = ("bounded", "sqrtcos", "none")
#: θ_d is multiplied by this before the Delaunay triangulation (module docstring,
#: step 3): < 1 makes the triangulation interpolate along θ_d at constant θ_h.
THETA_D_SCALE = 0.5
#: Default φ resolution (1°: the measured azimuths k·45° fall on the grid).
DEFAULT_N_PHI = 360
#: Finest default θ step of the table (keeps the table small for scattered data).
MIN_THETA_STEP = math.radians(1.0)
#: Angles closer than this are the same grid value (radians; float round-off).
ANGLE_TOL = 1e-9
#: Step used when the data's angles are not on a common grid.
SCATTERED_THETA_STEP = math.radians(2.0)

_ARRAYS = ("phi_grid", "theta_h_grid", "theta_d_grid", "table", "body")


@register
@dataclass
class HalfDiffModel(StoredSigma, ReflectanceModel):
    """A fitted ``kes-halfdiff`` model (module docstring).

    Attributes
    ----------
    channels : tuple of str
    phi_grid : ndarray (n_phi,)
        Half-vector azimuths j·2π/n_phi, radians, periodic.
    theta_h_grid, theta_d_grid : ndarray
        Uniform grids from 0, radians.
    table : ndarray (n_phi, n_theta_h, n_theta_d, C)
        Lobe quantity (``parameters["normalisation"]``), ≥ 0.
    body : ndarray (C,)
        Lambertian body term c, 1/sr.
    sigma : dict or None
        The numbers of its per-prediction σ (:mod:`kesbrdf.models.halfdiff_sigma`, eq. K1);
        None for files written before it.
    """

    kind: ClassVar[str] = KIND
    mappings: ClassVar[tuple[str, ...]] = (HALFDIFF,)
    #: kind="auto" checks a dense choice against the other kinds (fitting._dense_rule)
    auto_compare: ClassVar[str | None] = "dense"
    array_names: ClassVar[tuple[str, ...]] = _ARRAYS
    fit_options: ClassVar[tuple[str, ...]] = (
        "orientations", "fallback", "body", "noise_floor", "n_phi", "theta_step", "normalisation",
    )

    channels: tuple[str, ...]
    phi_grid: np.ndarray
    theta_h_grid: np.ndarray
    theta_d_grid: np.ndarray
    table: np.ndarray
    body: np.ndarray
    parameters: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    input_info: dict = field(default_factory=dict)
    kesbrdf_version: str = __version__
    sigma: dict | None = None
    #: the body's shape, eq. (B3) of :mod:`kesbrdf.models.body`; None: Lambertian
    body_law: BodyLaw | None = None

    #: (a, q, b₀, b₁) of its σ, eq. (K1) (:class:`kesbrdf.models.kes_sigma.StoredSigma`)
    sigma_scales: ClassVar[dict] = HALFDIFF_SIGMA_SCALES

    @property
    def orientations(self) -> int:
        return int(self.parameters.get("orientations", 4))

    def sigma_coordinates(self, wi, wr):
        """(φ_h, 2θ_h, d_slice) of eq. (K1) (:func:`kesbrdf.models.halfdiff_sigma.halfdiff_coordinates`)."""
        return halfdiff_coordinates(self, wi, wr)

    # -- kinds contract ---------------------------------------------------------
    def evaluate_unit(self, wi, wr, mapping: str) -> np.ndarray:
        phi_h, theta_h, theta_d = to_half_diff(wi, wr)
        q = lookup_halfdiff(self, phi_h, theta_h, theta_d)
        normalisation = self.parameters.get("normalisation", "sqrtcos")
        if normalisation != "none":
            q /= foreshortening(wi[:, 2], wr[:, 2], normalisation)[:, None]
        extrapolation = self.parameters.get("extrapolation", "hold")
        if extrapolation != "hold":  # in γ = 2θ_h, as the kes kind
            q *= fade(2.0 * theta_h, 2.0 * float(self.theta_h_grid[-1]), extrapolation)[:, None]
        q += self.body if self.body_law is None else self.body * self.body_law(wi[:, 2], wr[:, 2])[:, None]
        return q

    def mirror_behaviour(self) -> dict:
        return mirror_behaviour(self)

    # -- capabilities (kinds contract) -------------------------------------------
    def describe(self) -> str:
        n_phi, n_h, n_d = self.table.shape[:3]
        body = ("" if self.body_law is None else
                f", Fresnel-like body c g(cos theta_i) g(cos theta_r) (a {self.body_law.a:g}, p {self.body_law.p:g})")
        return (f"kes-halfdiff table {n_phi} x {n_h} x {n_d} over (phi_h, theta_h, theta_d), "
                f"{self.orientations} orientations{body}, channels {', '.join(self.channels)}")

    def render_plugin(self, mapping=None, extrapolation=None):
        """The ``kesbrdf_halfdiff`` plugin: its own (φ_h, θ_h, θ_d) parametrisation, so a
        KES ``mapping`` other than the default is an error."""
        if mapping not in (None, "deviation"):
            raise ModelError(f"mapping {mapping!r} applies to kes models only; a {self.kind} model has its own "
                             "parametrisation (drop --mapping)")
        return "kesbrdf_halfdiff", ({} if extrapolation is None else {"extrapolation": extrapolation})

    def to_payload(self):
        fields = {} if self.sigma is None else {"sigma": self.sigma}
        if self.body_law is not None:
            fields["body_law"] = self.body_law.to_dict()
        return fields, {name: getattr(self, name) for name in _ARRAYS}

    @classmethod
    def from_payload(cls, fields: dict, arrays: dict, shared: dict, source=None) -> "HalfDiffModel":
        arr = {name: arrays.get(name) for name in _ARRAYS}
        missing = [n for n, a in arr.items() if a is None]
        if missing:
            raise ModelError(f"{where(source)}missing array(s) {', '.join(missing)}")
        C = len(shared["channels"])
        grids = {n: arr[n] for n in ("phi_grid", "theta_h_grid", "theta_d_grid")}
        if any(g.ndim != 1 or g.size < 2 for g in grids.values()):
            raise ModelError(
                f"{where(source)}expected 1-D phi and theta grids of at least 2 values each, got shapes "
                f"{[g.shape for g in grids.values()]}"
            )
        check_uniform_grid(grids["phi_grid"], 2 * np.pi / grids["phi_grid"].size, "phi_grid", source)
        for name in ("theta_h_grid", "theta_d_grid"):
            g = grids[name]
            if not (np.isfinite(g[1]) and g[1] > 0):
                raise ModelError(f"{where(source)}{name}: expected a uniform grid from 0, got {g[:3].tolist()}...")
            check_uniform_grid(g, float(g[1]), name, source)
            if g[-1] > np.pi + 1e-9:
                raise ModelError(f"{where(source)}{name}: expected values up to pi, got {g[-1]!r}")
        expected = (grids["phi_grid"].size, grids["theta_h_grid"].size, grids["theta_d_grid"].size, C)
        if arr["table"].shape != expected or arr["body"].shape != (C,):
            raise ModelError(
                f"{where(source)}expected table of shape {expected} and body of shape ({C},), "
                f"got {arr['table'].shape} and {arr['body'].shape}"
            )
        check_values(arr["table"], "table", source)
        check_values(arr["body"], "body", source)
        for key, valid, default in (("normalisation", NORMALISATIONS, "sqrtcos"), ("extrapolation", EXTRAPOLATIONS, "hold")):
            value = shared["parameters"].get(key, default)
            if value not in valid:
                raise ModelError(
                    f"{where(source)}parameters.{key}: expected one of {', '.join(valid)}, got {str(value)[:40]!r}"
                )
        # absent in files written before it: no σ
        sigma = None if fields.get("sigma") is None else check_summary(fields["sigma"], source, SUPPORT_KEYS)
        return cls(**shared, **arr, sigma=sigma, body_law=BodyLaw.from_fields(fields, source))

    @classmethod
    def fit_measurement(cls, measurement, **options) -> "HalfDiffModel":
        check_fit_options(cls.kind, cls.fit_options, options)
        model = fit_halfdiff(measurement, **options)
        try:
            model.sigma = halfdiff_sigma_summary(measurement, model)
        except KesbrdfError:  # e.g. a line with a repeated theta_i: no σ rather than no model
            model.sigma = None
        return model

    @classmethod
    def usable_rows(cls, measurement, orientations=None):
        """(mask, reason): in-plane rows at the 3–4 orientations, any (θ_i, θ_r)."""
        m = measurement
        mask = np.zeros(len(m), bool)
        try:
            _, _, rows = _halfdiff_rows(m, orientations)
        except KesbrdfError as exc:
            return mask, f"the {KIND!r} kind cannot fit this measurement: {exc}"
        for r in rows:
            mask[r] = True
        parts = []
        n_out = int(np.count_nonzero(~m.is_in_plane))
        if n_out:
            parts.append(f"{n_out} out of the plane of incidence")
        other = int(np.count_nonzero(~mask)) - n_out
        if other:
            parts.append(f"{other} at orientations other than psi = 0, 45, 90, 135 deg")
        return mask, "; ".join(parts)

    @classmethod
    def sparse_rows(cls, measurement) -> str | None:
        """Why ``kind="auto"`` should not let this kind use the rows beyond a simpler kind's
        (or None): they fill too little of its (θ_h, θ_d) table (:func:`table_coverage`).

        Step 3 of the fit (module docstring) interpolates each slot's samples linearly
        over (θ_h, θ_d); a few incidence angles beside the paper's line leave most of the
        table between distant samples, where the Delaunay triangles spread a mirror peak
        over half the table (docs/decisions.md, "More rows never predict worse").
        """
        try:
            cover = table_coverage(measurement)
        except KesbrdfError:
            return None
        if cover >= MIN_TABLE_COVERAGE:
            return None
        return (f"its (theta_h, theta_d) table would be {100 * cover:.0f} % pinned by samples "
                f"(needs {100 * MIN_TABLE_COVERAGE:.0f} %: a dense in-plane grid)")


#: Smallest :func:`table_coverage` for which ``kind="auto"`` lets ``kes-halfdiff`` use
#: rows beyond a simpler kind's (``sparse_rows``).  Measured (kesbrdf plan groups, 6°
#: dense grid): dense 1.00; the paper protocol plus incidence lines or mirror samples
#: 0.18–0.43 (paper alone 0.18, + two lines 0.43, + five lines 0.38 at their finer
#: step), and those all predicted the hemispheres worse than ``kes`` on the paper rows
#: alone (docs/decisions.md).  3/4 sits in the gap: most of the table next to a sample.
MIN_TABLE_COVERAGE = 0.75


def table_coverage(m: Measurement, orientations=None) -> float:
    """Fraction of the in-plane (θ_h, θ_d) table nodes with a sample within 1.5 grid steps.

    Nodes: the measured in-plane triangle θ_h ≤ θ_d, θ_h + θ_d ≤ θ_max on the fit's
    grid (the data's natural step, :func:`fit_halfdiff` step 3); the fraction is the
    smallest over the half-azimuth slots.  A dense (θ_i, θ_r) grid reaches 1 (its
    checkerboard in (θ_h, θ_d) puts a sample next to every node); one incidence line
    pins about a fifth.
    """
    orientations, _, rows = _halfdiff_rows(m, orientations)
    used = np.concatenate(rows)
    theta_h, theta_d, _ = in_plane_half_diff(m.theta_i[used], m.theta_r[used])
    step, _ = _natural_step(np.concatenate([theta_h, theta_d]), None)
    theta_max = float(np.max(np.maximum(m.theta_i[used], m.theta_r[used])))
    H, D = np.meshgrid(_uniform_grid(theta_max / 2, step), _uniform_grid(theta_max, step), indexing="ij")
    inside = (H <= D + ANGLE_TOL) & (H + D <= theta_max + ANGLE_TOL)
    nodes = np.stack([H[inside], D[inside]], axis=-1)
    from scipy.spatial import cKDTree

    worst = 1.0
    for r in rows:
        th, td, upper = in_plane_half_diff(m.theta_i[r], m.theta_r[r])
        mirror = np.abs(m.theta_r[r] - m.theta_i[r]) < ANGLE_TOL
        for sel in (upper | mirror, ~upper | mirror):
            points = np.stack([th[sel], td[sel]], axis=-1)
            if not points.size:
                return 0.0
            nearest, _ = cKDTree(points).query(nodes)  # each node's nearest sample
            worst = min(worst, float(np.mean(nearest <= 1.5 * step)))
    return worst


# ---------------------------------------------------------------------------------
def _halfdiff_rows(m: Measurement, orientations):
    """(orientations, ψ's, in-plane rows per orientation) after the fit's checks."""
    orientations = select_orientations(m, orientations)
    psis = np.radians([0.0, 45.0, 90.0, 135.0][:orientations])
    source = m.source or "measurement"
    in_plane = np.flatnonzero(m.is_in_plane)
    rows = [in_plane[np.abs(m.psi[in_plane] - psi) < ORIENTATION_TOL] for psi in psis]
    used = np.concatenate(rows)
    finite = np.all(np.isfinite(m.values[used]), axis=1)
    if not finite.all():
        raise MeasurementError(
            f"{source}: expected finite values in the in-plane rows, got {int((~finite).sum())} NaN/inf row(s)"
        )
    for k, r in enumerate(rows):
        n_distinct = np.unique(np.round(m.theta_i[r] - m.theta_r[r], 9)).size
        if r.size < 2 or n_distinct < 2:
            raise MeasurementError(
                f"{source}: orientation psi = {np.degrees(psis[k]):g} deg needs samples at two or more "
                f"deviations theta_r - theta_i, got {n_distinct}"
            )
        mirror = np.abs(m.theta_r[r] - m.theta_i[r]) < ANGLE_TOL
        upper = m.theta_r[r] >= m.theta_i[r]
        for sel, op in ((upper | mirror, ">="), (~upper | mirror, "<=")):
            if np.count_nonzero(sel) < 2:
                raise MeasurementError(
                    f"{source}: orientation psi = {np.degrees(psis[k]):g} deg has fewer than two samples "
                    f"with theta_r {op} theta_i"
                )
    return orientations, psis, rows


def _natural_step(values, step):
    """Grid step: ``step`` if given, else the smallest spacing of the data's angles."""
    if step is not None:
        step = float(step)
        if not step > 0:
            raise KESError(f"expected a positive theta step, got {step!r}")
        return step, "given"
    raw = np.asarray(values, float)
    v = np.unique(np.round(raw / ANGLE_TOL) * ANGLE_TOL)
    spacing = np.diff(v)
    spacing = spacing[spacing > 10 * ANGLE_TOL]
    if spacing.size == 0:
        return SCATTERED_THETA_STEP, "scattered"
    candidate = float(spacing.min())
    on_grid = np.allclose(v / candidate, np.round(v / candidate), atol=1e-6)
    if on_grid and candidate >= MIN_THETA_STEP - ANGLE_TOL:
        # full precision from the raw angles (the rounding above is only a key)
        n = np.round(raw / candidate)
        return float(np.sum(n * raw) / np.sum(n * n)), "natural"
    return max(SCATTERED_THETA_STEP, MIN_THETA_STEP), "scattered"


def _uniform_grid(vmax: float, step: float) -> np.ndarray:
    n = int(math.ceil(vmax / step - 1e-6))
    return np.arange(max(n, 1) + 1) * step


def _in_plane_nodes(grid_h, grid_d, theta_max):
    """(θ_h, θ_d) of the in-plane pair each grid node reads, shape (n_h, n_d) each.

    θ_h is kept; θ_d is clamped into the measured in-plane range [θ_h, θ_max − θ_h]
    (module docstring, step 3): θ_d < θ_h reads θ_i = 0, θ_d + θ_h > θ_max reads
    max(θ_i, θ_r) = θ_max.
    """
    H, D = np.meshgrid(grid_h, grid_d, indexing="ij")
    return H, np.clip(D, H, np.maximum(theta_max - H, H))


def _resample_slot(theta_h, theta_d, q, H, D):
    """q of one slot's scattered samples at the nodes (H, D), shape H.shape + (C,)."""
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

    nodes = np.stack([H.ravel(), THETA_D_SCALE * D.ravel()], axis=-1)
    points = np.stack([theta_h, THETA_D_SCALE * theta_d], axis=-1)
    # merge duplicated geometries (repeated measurements) by averaging
    key = np.round(points / ANGLE_TOL).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse)
    q_mean = np.zeros((first.size, q.shape[1]))
    np.add.at(q_mean, inverse, q)
    q_mean /= counts[:, None]
    points = points[first]
    n_h_values = np.unique(key[:, 0]).size
    n_d_values = np.unique(key[:, 1]).size
    if points.shape[0] >= 3 and n_h_values > 1 and n_d_values > 1:
        out = LinearNDInterpolator(points, q_mean)(nodes)
        missing = np.isnan(out[:, 0])
        if missing.any():
            out[missing] = NearestNDInterpolator(points, q_mean)(nodes[missing])
    else:
        # one line of samples (e.g. the paper's θ_i + θ_r = 90°): 1-D along it
        axis = 0 if n_h_values > 1 or n_d_values == 1 else 1
        order = np.argsort(points[:, axis])
        x = points[order, axis]
        out = np.stack([np.interp(nodes[:, axis], x, q_mean[order, ch]) for ch in range(q.shape[1])], axis=-1)
    return out.reshape(H.shape + (q.shape[1],))


def fit_halfdiff(
    m: Measurement,
    orientations: int | None = None,
    fallback: str = "log",
    body="auto",
    noise_floor="auto",
    n_phi: int = DEFAULT_N_PHI,
    theta_step=None,
    normalisation: str = "bounded",
) -> HalfDiffModel:
    """Build the ``kes-halfdiff`` model from in-plane samples at several θ_i.

    Parameters
    ----------
    m : Measurement
        In-plane rows at ψ = 0, 45, 90° (and 135°), any (θ_i, θ_r) pairs; the more
        incidence angles, the more of the hemisphere is measured rather than assumed.
    orientations : {None, 3, 4}
        As :func:`kesbrdf.models.kes.fit`.
    fallback : {"log", "error"}
        What to do where K(φ) ≤ 0 between orientations (docs/method.md, "Interpolation over orientation"): log fallback with
        a recorded warning (default) or :class:`KESError`.
    body : "auto", "none" or float
        Lambertian body term c in 1/sr (module docstring).
    noise_floor : "auto" or float
        Floor of q, same unit as the table.
    n_phi : int
        φ cells, a multiple of 8.
    theta_step : float, optional
        (θ_h, θ_d) grid step, radians (default: the data's natural step).
    normalisation : {"bounded", "sqrtcos", "none"}
        What the table holds (:data:`NORMALISATIONS`, module docstring step 2).

    Raises
    ------
    MeasurementError
        Missing orientations, NaN values, or an orientation without samples on both
        sides of the mirror direction.
    KESError
        K(φ) ≤ 0 somewhere with ``fallback="error"``; bad options.

    Returns
    -------
    HalfDiffModel
    """
    if fallback not in FALLBACKS:
        raise KESError(f"unknown fallback {fallback!r}; expected one of {', '.join(FALLBACKS)}")
    if normalisation not in NORMALISATIONS:
        raise KESError(
            f"unknown normalisation {normalisation!r}; expected one of {', '.join(NORMALISATIONS)}"
        )
    if not (isinstance(n_phi, (int, np.integer)) and not isinstance(n_phi, bool) and n_phi > 0 and n_phi % 8 == 0):
        raise KESError(f"expected n_phi to be a positive multiple of 8, got {n_phi!r}")
    # 1. in-plane rows per orientation and their (θ_h, θ_d)
    orientations, psis, rows = _halfdiff_rows(m, orientations)
    C = m.n_channels
    source = m.source or "measurement"
    used = np.concatenate(rows)
    theta_h, theta_d, _ = in_plane_half_diff(m.theta_i[used], m.theta_r[used])

    # 1b. body term (kesbrdf.models.body): Fresnel-like c g(μ_i) g(μ_r) (eq. B3-B6) or B1
    c, law, body_mode, law_report = body_term(body, m.values[used], m.wi[used], m.wr[used], C)

    def shape(theta_i, theta_r):  # g(μ_i) g(μ_r) of the body (1: Lambertian)
        return body_factor(law, np.cos(theta_i), np.cos(theta_r))

    def weight(theta_i, theta_r):
        if normalisation == "none":
            return np.ones_like(np.asarray(theta_i, float))
        return foreshortening(np.cos(theta_i), np.cos(theta_r), normalisation)

    # 2–3. regular (θ_h, θ_d) grid; per slot, the lobe part of q resampled onto it
    step, step_mode = _natural_step(np.concatenate([theta_h, theta_d]), theta_step)
    grid_h = _uniform_grid(float(theta_h.max()), step)
    grid_d = _uniform_grid(float(theta_d.max()), step)
    theta_max = float(np.max(np.maximum(m.theta_i[used], m.theta_r[used])))
    H, D = _in_plane_nodes(grid_h, grid_d, theta_max)
    w_nodes = weight(D - H, D + H)  # in-plane √(cos θ_i cos θ_r) at the nodes read
    slots = kes.half_slots(orientations)
    q_half = np.full((grid_h.size, grid_d.size, 8, C), np.nan)
    slot_counts = {}
    for k, r in enumerate(rows):
        th, td, upper = in_plane_half_diff(m.theta_i[r], m.theta_r[r])
        mirror = np.abs(m.theta_r[r] - m.theta_i[r]) < ANGLE_TOL
        lobe = (m.values[r] - c * shape(m.theta_i[r], m.theta_r[r])[:, None]) * weight(m.theta_i[r], m.theta_r[r])[:, None]
        for slot, sel in ((k, upper | mirror), (k + 4, ~upper | mirror)):
            if np.count_nonzero(sel) < 2:
                raise MeasurementError(
                    f"{source}: orientation psi = {np.degrees(psis[k]):g} deg has fewer than two samples "
                    f"with theta_r {'>=' if slot < 4 else '<='} theta_i"
                )
            q_half[:, :, slot, :] = _resample_slot(th[sel], td[sel], lobe[sel], H, D)
            slot_counts[str(slot)] = int(np.count_nonzero(sel))
    # 4. body back in: KES works on the measured quantity (as kesbrdf.models.kes.fit)
    body_q = c * (w_nodes * shape(D - H, D + H))[..., None]  # (h, d, C)
    q_half[:, :, slots, :] += body_q[:, :, None, :]
    # θ_i = θ_r = 0 is one geometry for every ψ: its samples are averaged (with noise
    # they differ, and the pair has no azimuth to tell them apart)
    normal_pair = {}
    if all(np.any((m.theta_i[r] < ANGLE_TOL) & (m.theta_r[r] < ANGLE_TOL)) for r in rows):
        at_normal = q_half[0, 0][slots]  # (slots, C)
        mean = at_normal.mean(axis=0)
        q_half[0, 0, slots, :] = mean
        normal_pair = {
            "averaged": True,
            "max_rel_spread": float(
                np.max(np.ptp(at_normal, axis=0) / np.maximum(np.abs(mean), np.finfo(float).tiny))
            ),
        }

    # 5. noise floor
    q_used = q_half[:, :, slots, :]
    if isinstance(noise_floor, str) and noise_floor == "auto":
        floor = np.maximum(RELATIVE_NOISE_FLOOR * np.nanmax(q_used, axis=(0, 1, 2)), np.finfo(float).tiny)
    else:
        floor = np.broadcast_to(np.asarray(noise_floor, float), (C,)).copy()
        if np.any(~(floor > 0)):
            raise KESError(f"expected a positive noise floor, got {noise_floor!r}")
    low = q_used < floor
    floored = {
        "nodes": int(np.count_nonzero(low)),
        "of": int(low.size),
        "per_channel": {ch: int(np.count_nonzero(low[..., i])) for i, ch in enumerate(m.channels)},
        "per_azimuth_deg": {
            f"{int(round(np.degrees(kes.HALF_AZIMUTHS[s])))}": int(np.count_nonzero(low[:, :, j, :]))
            for j, s in enumerate(slots)
        },
    }
    q_half[:, :, slots, :] = np.maximum(q_used, floor)

    # 6. KES over φ at every (θ_h, θ_d) node, vectorised over nodes and channels
    phi_grid = np.arange(n_phi) * (2 * np.pi / n_phi)
    K = kes.interpolate_circle(1.0 / q_half.transpose(0, 1, 3, 2), phi_grid, orientations)  # (h, d, C, φ)
    bad = np.any(~(K > 0), axis=(2, 3))  # (h, d)
    fallback_info = {"nodes": 0, "theta_h_deg": [], "theta_d_deg_range": []}
    if bad.any():
        bi, bj = np.nonzero(bad)
        if fallback == "error":
            raise KESError(
                f"K(phi) = 1/rho <= 0 between the measured orientations at theta_h = "
                f"{math.degrees(grid_h[bi[0]]):.4g} deg, theta_d = {math.degrees(grid_d[bj[0]]):.4g} deg "
                f"({bi.size} node(s) affected): warp and weft differ too much for the KES form; use "
                "fallback='log' (the default; kesbrdf fit without --strict) to interpolate log rho there instead"
            )
        q_log = kes.interpolate_circle_log(q_half[bi, bj].transpose(0, 2, 1), phi_grid, orientations)
        K[bi, bj] = 1.0 / q_log
        fallback_info = {
            "nodes": int(bi.size),
            "theta_h_deg": sorted({round(float(np.degrees(grid_h[i])), 6) for i in bi}),
            "theta_d_deg_range": [
                round(float(np.degrees(grid_d[bj].min())), 6),
                round(float(np.degrees(grid_d[bj].max())), 6),
            ],
        }
    # 7. split off the body again: the table holds the lobe
    table = np.transpose(1.0 / K, (3, 0, 1, 2)) - body_q[None]  # (φ, h, d, C)
    total = np.abs(table + body_q[None])
    dips = table < -1e-12 * total
    clamped = {
        "entries": int(np.count_nonzero(dips)),
        "of": int(table.size),
        # deepest dip of Q(φ) below the body, relative to Q: what the clamp removed
        "max_rel": float(np.max(-table[dips] / np.maximum(total[dips], np.finfo(float).tiny), initial=0.0)),
    }
    table = np.ascontiguousarray(np.maximum(table, 0.0))

    diagnostics = {
        "warnings": [fallback_warning("theta_h", fallback_info["theta_h_deg"], fallback_info["nodes"])]
        if fallback_info["nodes"] else [],
        "floored": floored,
        "noise_floor": floor.tolist(),
        "fallback": fallback_info,
        "unused_rows": int(len(m) - used.size),
        "samples_per_azimuth_slot": slot_counts,
        "theta_step_deg": round(math.degrees(step), 9),
        "theta_step_mode": step_mode,
        "lobe_clamped": clamped,
        "normal_pair": normal_pair,
    }
    if law_report is not None:
        diagnostics["body_law"] = law_report
    return HalfDiffModel(
        channels=tuple(m.channels),
        phi_grid=phi_grid,
        theta_h_grid=grid_h,
        theta_d_grid=grid_d,
        table=table,
        body=c,
        parameters={
            "orientations": orientations,
            "fallback": fallback,
            "body": body_mode if body_mode != "value" else c.tolist(),
            "noise_floor": noise_floor if isinstance(noise_floor, str) else floor.tolist(),
            "normalisation": normalisation,
            "extrapolation": "fade",
            "theta_interpolation": "linear",
            "theta_d_scale": THETA_D_SCALE,
            "n_phi": int(n_phi),
        },
        diagnostics=diagnostics,
        input_info=m.input_info(),
        body_law=law,
    )


# ---------------------------------------------------------------------------------
def lookup_halfdiff(model: HalfDiffModel, phi_h, theta_h, theta_d) -> np.ndarray:
    """Trilinear lookup of the table at (φ_h, θ_h, θ_d), shape (..., C).

    φ is periodic; θ_h and θ_d are clamped to their grids.  NaN in gives NaN out.
    """
    phi_h, theta_h, theta_d = np.broadcast_arrays(
        np.asarray(phi_h, float), np.asarray(theta_h, float), np.asarray(theta_d, float)
    )
    T = model.table
    n_phi, n_h, n_d = T.shape[:3]
    u = np.mod(phi_h, 2 * np.pi) * (n_phi / (2 * np.pi))
    v = np.clip(theta_h, 0.0, model.theta_h_grid[-1]) / (model.theta_h_grid[1] - model.theta_h_grid[0])
    w = np.clip(theta_d, 0.0, model.theta_d_grid[-1]) / (model.theta_d_grid[1] - model.theta_d_grid[0])
    nan = ~(np.isfinite(u) & np.isfinite(v) & np.isfinite(w))
    u, v, w = (np.where(nan, 0.0, a) for a in (u, v, w))
    i0 = np.floor(u).astype(np.intp)
    fu = (u - i0)[..., None]
    i0 %= n_phi
    i1 = (i0 + 1) % n_phi
    j0 = np.minimum(np.floor(v).astype(np.intp), n_h - 1)
    fv = (v - j0)[..., None]
    j1 = np.minimum(j0 + 1, n_h - 1)
    k0 = np.minimum(np.floor(w).astype(np.intp), n_d - 1)
    fw = (w - k0)[..., None]
    k1 = np.minimum(k0 + 1, n_d - 1)

    def along_phi(j, k):
        return T[i0, j, k] * (1 - fu) + T[i1, j, k] * fu

    q = (along_phi(j0, k0) * (1 - fv) + along_phi(j1, k0) * fv) * (1 - fw) + (
        along_phi(j0, k1) * (1 - fv) + along_phi(j1, k1) * fv
    ) * fw
    return np.where(nan[..., None], np.nan, q)


def evaluate_halfdiff(model: HalfDiffModel, wi, wr) -> np.ndarray:
    """f_r(wi, wr) of a ``kes-halfdiff`` model in 1/sr, shape broadcast(wi, wr)[:-1] + (C,).

    .. math:: f_r = c + T(\\phi_h, \\theta_h, \\theta_d) / w(\\theta_i, \\theta_r)

    (w of :func:`kesbrdf.models.mappings.foreshortening`; w = 1 for ``normalisation="none"``).  Zero when either
    direction is at or below the horizon; NaN in gives NaN out
    (:func:`kesbrdf.models.mappings.evaluate_pairs`).  Same as ``model.evaluate(wi, wr)``.

    >>> from kesbrdf.measure.gonio import measure
    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> m = measure(AnisotropicWard(0.2, 0.3), protocol="dense", step_deg=10)
    >>> model = fit_halfdiff(m)
    >>> bool(np.allclose(evaluate_halfdiff(model, m.wi, m.wr), m.values, rtol=1e-9))
    True
    """
    return model.evaluate(wi, wr)


def mirror_behaviour(model: HalfDiffModel, n_theta_h: int = 3, theta_d_deg=(0.0, 30.0, 60.0)) -> dict:
    """How the lobe varies with φ_h as θ_h → 0 (the analogue of the ``kes`` kind's γ → 0
    report, docs/method.md, "Diagnostics"): max/min of the table over φ at the first θ_h grid values, for a
    few θ_d, per channel.  The measured mirror peaks differ between orientations, so
    φ_h is a discontinuity at h = z.
    """
    out = {}
    step_d = model.theta_d_grid[1] - model.theta_d_grid[0]
    for theta_d in theta_d_deg:
        k = int(min(round(math.radians(theta_d) / step_d), model.theta_d_grid.size - 1))
        rows = {}
        for j in range(min(n_theta_h, model.theta_h_grid.size)):
            q = model.table[:, j, k, :]
            qmin = np.maximum(q.min(axis=0), np.finfo(float).tiny)
            rows[f"{np.degrees(model.theta_h_grid[j]):.3g}"] = (q.max(axis=0) / qmin).tolist()
        out[f"{np.degrees(model.theta_d_grid[k]):.3g}"] = rows
    return {"q_max_over_min_by_theta_d_deg_theta_h_deg": out, "channels": list(model.channels)}


# ---------------------------------------------------------------------------------
def to_dict(model: HalfDiffModel) -> dict:
    """The model file document (:func:`kesbrdf.io.model_file.model_to_dict`)."""
    from kesbrdf.io.model_file import model_to_dict

    return model_to_dict(model)


def from_dict(doc, source=None) -> HalfDiffModel:
    """Inverse of :func:`to_dict`; errors name ``source``."""
    from kesbrdf.io.model_file import model_from_dict

    model = model_from_dict(doc, source)
    if not isinstance(model, HalfDiffModel):
        raise ModelError(f"{where(source)}expected model kind {KIND!r}, got {model.kind!r}")
    return model
