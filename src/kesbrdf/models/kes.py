r"""The anisotropic reflection model: the table ρ(φ, γ) (paper STEP 3, docs/method.md, "From the table to a BRDF").

:func:`fit` turns in-plane measurements at ψ = 0, π/4, π/2 (and 3π/4) into a
table of the lobe quantity

.. math:: q(\phi, \gamma) = (f_r - c)\,w(\theta_i, \theta_r)

(w the foreshortening weight, :func:`kesbrdf.models.mappings.foreshortening`: paper eq. 3's
√(cos θ_i cos θ_r), bounded toward grazing angles; ``parameters["normalisation"]``)
over the whole circle of deviation azimuths φ ∈ [0, 2π) and deviations γ ≥ 0, plus a
Lambertian body term c (docs/method.md, "The body term").  The table *is* the model: every consumer (numpy
BRDF, Mitsuba plugin, browser viewer) evaluates it by the same bilinear lookup
(``docs/formats.md``).

How the table is filled
-----------------------
1. Signed γ = θ_r − θ_i of each in-plane sample at orientation ψ becomes a
   half-sample at deviation azimuth ψ (γ > 0) or ψ + π (γ < 0) with |γ|; at γ = 0
   both halves get the same sample (the plane of incidence, docs/method.md, "From the table to a BRDF").
2. Body: ``body="auto"`` fits the Fresnel-like body c g(cos θ_i) g(cos θ_r) of eq. B3
   of :mod:`kesbrdf.models.body` to the samples and keeps it when its shape is
   Fresnel-like (eq. B5); otherwise, and with ``body="lambertian"``, c = max(0, min f_r)
   per channel over the in-plane samples (the darkest reading is an upper bound of the
   diffuse floor, eq. B1, the rule every kind shares; noise makes it a slight
   underestimate, which only moves energy to the lobe); ``"none"`` is c = 0 (the paper's
   pure lobe); a number sets c.  The body is split off after the interpolation over φ
   (step 5), so it changes nothing in the plane of incidence.
3. Noise floor: q is floored at ``noise_floor`` (default: 1e-4 × the channel's peak
   q, a 14-bit dynamic range) so that K = 1/q stays finite; every floored
   half-sample is recorded in ``diagnostics["floored"]``.
4. Each of the eight half-sample curves is resampled onto a uniform γ grid
   (linear in q; the grid contains every measured |γ| when they are uniformly
   spaced, so the measured values are kept exactly).
5. For every γ of the grid, K = 1/q is interpolated over φ by :mod:`kesbrdf.models.interpolation`.
   Where K(φ) ≤ 0 somewhere (the hazard of docs/method.md, "Interpolation over orientation", common on satins), the default
   ``fallback="log"`` interpolates log q instead at that γ, records it in
   ``diagnostics["fallback_gamma_deg"]`` and adds a one-line warning naming the γ
   affected to ``diagnostics["warnings"]``; ``fallback="error"`` (``kesbrdf fit
   --strict``) raises :class:`~kesbrdf.errors.KESError` instead.

Baselines (``interpolation="nearest"`` or ``"linear"``) fill the same table with the
nearest measured half-sample or linear interpolation over φ, so they are evaluated
with the same BRDF machinery and compared on equal terms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from kesbrdf.models import interpolation as kes
from kesbrdf._version import __version__
from kesbrdf.errors import KESError, KesbrdfError, MeasurementError, ModelError, where
from kesbrdf.models.base import ReflectanceModel, register, check_fit_options
from kesbrdf.models.body import BodyLaw, body_term, line_body_factor
from kesbrdf.models.kes_sigma import KES_SIGMA_SCALES, StoredSigma, check_summary, kes_coordinates, sigma_summary
from kesbrdf.models.mappings import (
    EXTRAPOLATIONS,
    FIT_MAPPING,
    MAPPINGS,
    TABLE_MAPPINGS,
    NORMALISATIONS,
    PAPER_MIN_SIN_BETA,
    fade,
    foreshortening,
    line_foreshortening,
    to_phi_gamma,
)
from kesbrdf.measure.measurement import Measurement
from kesbrdf.models.table import (  # noqa: F401  (lookup, check_*: the table toolkit, re-exported)
    GRID_TOL,
    check_uniform_grid,
    check_values,
    gamma0_behaviour,
    lookup,
    lookup_unit,
)

__all__ = [
    "Model",
    "fit",
    "lookup",
    "INTERPOLATIONS",
    "FALLBACKS",
    "select_orientations",
    "incidence_line",
    "line_weight",
    "fill_table",
    "fallback_warning",
]

INTERPOLATIONS = ("kes", "nearest", "linear")
FALLBACKS = ("error", "log")
#: Interpolated ρ above this multiple of the brightest measured orientation at a γ is a
#: spike of the KES interpolant (K = 1/ρ near 0), handled like K ≤ 0 (docs/models.md).
OVERSHOOT = 4.0

#: Orientation match tolerance when recognising ψ = 0/45/90/135° in a file.
ORIENTATION_TOL = math.radians(0.5)
#: Default noise floor relative to each channel's peak q.
RELATIVE_NOISE_FLOOR = 1e-4
#: Default φ resolution of the table (1°: measured azimuths k·45° fall on the grid).
DEFAULT_N_PHI = 360
#: Finest default γ step of the table.
MAX_GAMMA_STEP = math.radians(1.0)


_ARRAYS = ("phi_grid", "gamma_grid", "table", "body", "gamma_nodes", "q_nodes")


@register
@dataclass
class Model(StoredSigma, ReflectanceModel):
    """A fitted extended-KES model, kind ``"kes"`` (module docstring, docs/formats.md).

    Attributes
    ----------
    channels : tuple of str
    phi_grid : ndarray (n_phi,)
        Deviation azimuths j·2π/n_phi, radians.
    gamma_grid : ndarray (n_gamma,)
        Uniform deviations from 0, radians.
    table : ndarray (n_phi, n_gamma, C)
        Lobe quantity q, 1/sr, ≥ 0.
    body : ndarray (C,)
        Body c, 1/sr: Lambertian, or times g(cos θ_i) g(cos θ_r) of ``body_law``.
    gamma_nodes, q_nodes : ndarray
        The measured half-sample nodes (for plots and the viewer).
    sigma : dict or None
        The numbers of its per-prediction σ (:mod:`kesbrdf.models.kes_sigma`, eq. K1).
    body_law : BodyLaw or None
        The Fresnel-like shape of the body (:mod:`kesbrdf.models.body`, eq. B3); None: a
        Lambertian body (every file written before it).
    """

    kind: ClassVar[str] = "kes"
    mappings: ClassVar[tuple[str, ...]] = MAPPINGS
    array_names: ClassVar[tuple[str, ...]] = _ARRAYS
    #: kind="auto" compares the paper-protocol KES choice with the prior by leave-one-orientation-out
    auto_compare: ClassVar[str | None] = "loo"
    fit_options: ClassVar[tuple[str, ...]] = (
        "orientations", "fallback", "body", "noise_floor", "interpolation", "n_phi", "gamma_step",
        "normalisation", "extrapolation", "mapping",
    )

    channels: tuple[str, ...]
    phi_grid: np.ndarray
    gamma_grid: np.ndarray
    table: np.ndarray
    body: np.ndarray
    gamma_nodes: np.ndarray
    q_nodes: np.ndarray
    parameters: dict = field(default_factory=dict)
    diagnostics: dict = field(default_factory=dict)
    input_info: dict = field(default_factory=dict)
    kesbrdf_version: str = __version__
    #: What the fit's own data say about the table's error (:func:`kesbrdf.models.kes_sigma.sigma_summary`):
    #: the σ of eq. (K1); None for files written before it, baselines and tabulated tables.
    sigma: dict | None = None
    #: eq. (B3) of :mod:`kesbrdf.models.body`; None: Lambertian.
    body_law: BodyLaw | None = None

    @property
    def gamma_max(self) -> float:
        return float(self.gamma_grid[-1])

    @property
    def orientations(self) -> int:
        return int(self.parameters.get("orientations", 4))

    @property
    def normalisation(self) -> str:
        """What the table holds, :data:`kesbrdf.models.mappings.NORMALISATIONS`: ``bounded``, or
        ``sqrtcos`` for files written before it (their tables were fitted so)."""
        return str(self.parameters.get("normalisation", "sqrtcos"))

    @property
    def extrapolation(self) -> str:
        """The lobe beyond γ_max, :data:`kesbrdf.models.mappings.EXTRAPOLATIONS`: ``fade``, or
        ``hold`` for files written before it."""
        return str(self.parameters.get("extrapolation", "hold"))

    @property
    def default_mapping(self) -> str:
        """The mapping the table was fitted for, ``parameters["mapping"]``: ``halfvector``
        for new fits (:data:`kesbrdf.models.mappings.FIT_MAPPING`), ``deviation`` for files
        that record none (written before it).  Every consumer that is not told a mapping
        evaluates, renders and exports with this one."""
        recorded = self.parameters.get("mapping") if isinstance(self.parameters, dict) else None
        return recorded if recorded in MAPPINGS else MAPPINGS[0]

    @property
    def line_sum(self) -> float:
        """θ_i + θ_r of the incidence line the table was fitted on, radians (90° by default)."""
        value = self.diagnostics.get("incidence_line_deg", self.parameters.get("incidence_line_deg", 90.0))
        try:
            return math.radians(float(value))
        except (TypeError, ValueError):
            return math.pi / 2

    @property
    def sample_frame_warp(self) -> float:
        """Sample-frame azimuth of the warp, radians (scattered fits; 0 otherwise)."""
        try:
            return math.radians(float(self.parameters.get("warp_offset_deg", 0.0) or 0.0))
        except (TypeError, ValueError):
            return 0.0

    # -- evaluation (kinds contract) ------------------------------------------
    def evaluate_unit(self, wi, wr, mapping: str) -> np.ndarray:
        """f_r of unit rows above the horizon (kinds contract), shape (n, C)."""
        cos_theta_i = wi[:, 2]
        cos_theta_r = wr[:, 2]
        if mapping == "paper":
            inv_norm = 1.0 / np.sqrt(cos_theta_i * cos_theta_r)
            # eq. 3–4 as paper_phi_gamma, with sin β = 2h√(1 − h²) for β = 2 arcsin h
            # and cos θ_r taken from the vector (same values, fewer transcendental calls)
            theta_i = np.arccos(np.minimum(cos_theta_i, 1.0))
            theta_r = np.arccos(np.minimum(cos_theta_r, 1.0))
            phi_i = np.arctan2(wi[:, 1], wi[:, 0])
            phi_r = np.arctan2(wr[:, 1], wr[:, 0])
            gamma = theta_r - theta_i
            s = np.sin(phi_r - phi_i)
            h = np.minimum(0.5 * np.sqrt(s * s + cos_theta_r * cos_theta_r), 1.0)
            sin_beta = np.maximum(2.0 * h * np.sqrt(1.0 - h * h), PAPER_MIN_SIN_BETA)
            phi = np.pi / 2 - (phi_i + phi_r)
            phi[gamma < 0] += np.pi
            phi = np.mod(phi, 2 * np.pi)
            # ρ_KES is the measured quantity q on the paper's θ_i + θ_r = 90° line,
            # body included: c·√(cos θ_i cos θ_r) = c·√(cos γ / 2) there.
            rho = self.lookup_unit(phi, np.abs(gamma))
            if self.normalisation != "sqrtcos":  # back to the measured (f − c)·√(cos θ_i cos θ_r)
                g = np.abs(gamma)
                S = self.line_sum
                rho *= (line_foreshortening(g, S, "sqrtcos") / line_foreshortening(g, S, self.normalisation))[:, None]
            rho += self.body * (np.sqrt(np.maximum(np.cos(gamma), 0.0) * 0.5)
                                * self.line_body_shape(np.abs(gamma)))[:, None]
            rho *= (inv_norm / sin_beta)[:, None]
            return rho
        phi, gamma = to_phi_gamma(wi, wr, mapping)
        q = self.lookup_unit(phi, gamma)
        scale = 1.0 / foreshortening(cos_theta_i, cos_theta_r, self.normalisation)
        if self.extrapolation != "hold":
            scale *= fade(gamma, self.gamma_max, self.extrapolation)
        q *= scale[:, None]
        q += self.body if self.body_law is None else self.body * self.body_law(cos_theta_i, cos_theta_r)[:, None]
        return q

    def line_body_shape(self, gamma) -> np.ndarray:
        """g(cos θ_i) g(cos θ_r) of the body on the table's incidence line at deviation |γ|
        (θ_{i,r} = (S ∓ |γ|)/2); 1 for a Lambertian body."""
        return line_body_factor(self.body_law, gamma, self.line_sum)

    def lookup_unit(self, phi, gamma) -> np.ndarray:
        """Bilinear lookup for φ ∈ [0, 2π], γ ≥ 0 (finite), shape (n, C) (:func:`kesbrdf.models.table.lookup_unit`)."""
        return lookup_unit(self, phi, gamma)

    def mirror_behaviour(self) -> dict:
        """How the lobe varies with φ as γ → 0 (:func:`gamma0_behaviour`)."""
        return gamma0_behaviour(self)

    # -- capabilities (kinds contract) -------------------------------------------
    @property
    def has_table(self) -> bool:
        return True

    #: (a, q, b₀, b₁) of its σ, eq. (K1) (:class:`kesbrdf.models.kes_sigma.StoredSigma`)
    sigma_scales: ClassVar[dict] = KES_SIGMA_SCALES

    def sigma_coordinates(self, wi, wr):
        """(φ, γ, d_slice) of eq. (K1) (:func:`kesbrdf.models.kes_sigma.kes_coordinates`)."""
        return kes_coordinates(self, wi, wr)

    def table_view(self, n_phi=None, n_gamma=None) -> "Model":
        """The model itself: its table is the (φ, γ) table."""
        return self

    @classmethod
    def tabulate(cls, model, n_phi=None, n_gamma=None) -> "Model":
        """The (φ, γ) table of any model through its evaluation (:func:`kesbrdf.models.table.tabulate`)."""
        from kesbrdf.models.table import tabulate

        fields = tabulate(model, n_phi, n_gamma)
        fields["kesbrdf_version"] = fields["kesbrdf_version"] or cls.kesbrdf_version
        return cls(**fields)

    def describe(self) -> str:
        p, d = self.parameters, self.diagnostics
        table = (f"kes table {self.phi_grid.size} x {self.gamma_grid.size} over (phi, gamma) up to "
                 f"{math.degrees(self.gamma_max):.3g} deg, channels {', '.join(self.channels)}")
        if p.get("tabulated_from"):
            return f"{table}, tabulated from a {p['tabulated_from']!r} model"
        if p.get("fit") == "scattered":
            return (f"scattered fit of {d.get('n_used', '?')} samples, warp at {float(p.get('warp_offset_deg', 0.0)):.1f} deg "
                    f"({p.get('warp_offset_rule', 'given')}), symmetry {p.get('symmetry')}, body {self.body.tolist()}; {table}")
        body = ("" if self.body_law is None else
                f", Fresnel-like body c g(cos theta_i) g(cos theta_r) (a {self.body_law.a:g}, p {self.body_law.p:g})")
        return f"{self.orientations} orientations, {len(self.gamma_nodes)} gamma nodes{body}; {table}"

    def refit_options(self) -> dict:
        """As the base class, without ``orientations`` (the subset says how many it has)."""
        options = super().refit_options()
        if "_fit_memory" not in self.__dict__:
            options.pop("orientations", None)
        return options

    # -- model file (kinds contract) -------------------------------------------
    def to_payload(self):
        fields = {} if self.sigma is None else {"sigma": self.sigma}
        if self.body_law is not None:
            fields["body_law"] = self.body_law.to_dict()
        return fields, {name: getattr(self, name) for name in _ARRAYS}

    @classmethod
    def from_payload(cls, fields: dict, arrays: dict, shared: dict, source=None) -> "Model":
        """Rebuild from the model file's arrays; shapes, grids and values are checked."""
        arr = {name: arrays.get(name) for name in _ARRAYS}
        missing = [n for n, a in arr.items() if a is None]
        if missing:
            raise ModelError(f"{where(source)}missing array(s) {', '.join(missing)}")
        C = len(shared["channels"])
        phi_grid, gamma_grid, table, body = arr["phi_grid"], arr["gamma_grid"], arr["table"], arr["body"]
        if phi_grid.ndim != 1 or gamma_grid.ndim != 1 or phi_grid.size < 2 or gamma_grid.size < 2:
            raise ModelError(
                f"{where(source)}expected 1-D phi and gamma grids of at least 2 values each, got shapes "
                f"{phi_grid.shape} and {gamma_grid.shape}"
            )
        n_phi, n_gamma = phi_grid.size, gamma_grid.size
        check_uniform_grid(phi_grid, 2 * np.pi / n_phi, "phi_grid", source)
        if not np.all(np.isfinite(gamma_grid)) or not gamma_grid[1] > 0:
            raise ModelError(f"{where(source)}gamma_grid: expected a uniform grid from 0, got {gamma_grid[:3].tolist()}...")
        check_uniform_grid(gamma_grid, float(gamma_grid[1]), "gamma_grid", source)
        if gamma_grid[-1] > np.pi + GRID_TOL:
            raise ModelError(f"{where(source)}gamma_grid: expected values up to pi, got {gamma_grid[-1]!r}")
        if table.shape != (n_phi, n_gamma, C) or body.shape != (C,):
            raise ModelError(
                f"{where(source)}expected table of shape ({n_phi}, {n_gamma}, {C}) and body of "
                f"shape ({C},), got {table.shape} and {body.shape}"
            )
        check_values(table, "table", source)
        check_values(body, "body", source)
        params = shared.get("parameters") or {}
        for key, valid, default in (("normalisation", NORMALISATIONS, "sqrtcos"), ("extrapolation", EXTRAPOLATIONS, "hold")):
            value = params.get(key, default)
            if value not in valid:
                raise ModelError(
                    f"{where(source)}parameters.{key}: expected one of {', '.join(valid)}, got {str(value)[:40]!r}"
                )
        nodes, q_nodes = arr["gamma_nodes"], arr["q_nodes"]
        if nodes.ndim != 1 or q_nodes.shape != (nodes.size, 8, C) or not np.all(np.isfinite(nodes)):
            raise ModelError(
                f"{where(source)}expected finite gamma_nodes (n,) and q_nodes (n, 8, {C}), got "
                f"{nodes.shape} and {q_nodes.shape}"
            )
        if np.any(np.isinf(q_nodes)):
            raise ModelError(f"{where(source)}q_nodes: expected finite values or NaN (unmeasured), got inf")
        sigma = None
        if fields.get("sigma") is not None:  # absent in files written before it: no σ
            sigma = check_summary(fields["sigma"], source)
        # absent in files written before it: Lambertian
        return cls(**shared, **arr, sigma=sigma, body_law=BodyLaw.from_fields(fields, source))

    # -- fitting (kinds contract) ----------------------------------------------
    @classmethod
    def fit_measurement(cls, measurement, **options) -> "Model":
        check_fit_options(cls.kind, cls.fit_options, options)
        model = fit(measurement, **options)
        if model.parameters.get("interpolation") == "kes":  # the σ is calibrated for the KES form only
            try:
                model.sigma = sigma_summary(measurement, model)
            except KesbrdfError:  # e.g. a line with a repeated theta_i: no σ rather than no model
                model.sigma = None
        return model

    @classmethod
    def usable_rows(cls, measurement, orientations=None):
        """(mask, reason): the rows :func:`fit` uses (one incidence line, 3–4 orientations)."""
        m = measurement
        mask = np.zeros(len(m), bool)
        try:
            orientations, _, at, line_sum = _kes_rows(m, orientations)
        except KesbrdfError as exc:
            return mask, f"the 'kes' kind cannot fit this measurement: {exc}"
        for rows in at.values():
            mask[rows[np.abs(m.theta_i[rows] + m.theta_r[rows] - line_sum) < 1e-6]] = True
        in_plane = m.is_in_plane
        parts = []
        n_out = int(np.count_nonzero(~in_plane))
        if n_out:
            parts.append(f"{n_out} out of the plane of incidence")
        other = in_plane & ~np.isin(np.arange(len(m)), np.concatenate(list(at.values())))
        if other.any():
            parts.append(f"{int(other.sum())} at orientations other than psi = "
                         f"{', '.join(f'{d:g}' for d in (0, 45, 90, 135)[:orientations])} deg")
        off = int(np.count_nonzero(~mask)) - n_out - int(other.sum())
        if off:
            parts.append(f"{off} off the incidence line theta_i + theta_r = {math.degrees(line_sum):g} deg "
                         "(several incidence angles: the 'kes-halfdiff' kind uses them)")
        return mask, "; ".join(parts)


# ---------------------------------------------------------------------------------
def fallback_warning(what: str, values_deg, n_total: int | None = None) -> str:
    """The one-line warning of a log fallback (docs/method.md, "Interpolation over orientation"), naming the angles affected."""
    v = sorted({round(float(x), 3) for x in values_deg})
    if len(v) <= 6:
        named = ", ".join(f"{x:g}" for x in v)
    else:
        named = f"{v[0]:g} to {v[-1]:g} ({len(v)} values)"
    return (
        f"K(phi) = 1/rho <= 0 between the measured orientations at {what} = {named} deg"
        f"{'' if n_total is None else f' ({n_total} node(s))'}: interpolated log rho there "
        "(fallback 'log'; --strict or fallback='error' makes this an error)"
    )


def select_orientations(m: Measurement, orientations):
    present = m.orientations()
    if present.size == 0:
        raise MeasurementError(
            f"{m.source or 'measurement'}: KES needs in-plane samples (psi_deg column) at "
            "psi = 0, 45, 90 (and 135) deg; got none"
        )
    wanted = np.radians([0.0, 45.0, 90.0, 135.0])
    found = [bool(np.any(np.abs(present - w) < ORIENTATION_TOL)) for w in wanted]
    missing3 = [d for d, ok in zip((0, 45, 90), found[:3]) if not ok]
    got = ", ".join(f"{x:g}" for x in np.degrees(present))
    if missing3:
        raise MeasurementError(
            f"{m.source or 'measurement'}: KES needs orientations psi = 0, 45, 90 deg; "
            f"missing {', '.join(map(str, missing3))} (got {got})"
        )
    if orientations is None:
        orientations = 4 if found[3] else 3
    if orientations not in (3, 4):
        raise KESError(f"expected orientations 3 or 4, got {orientations!r}")
    if orientations == 4 and not found[3]:
        raise MeasurementError(
            f"{m.source or 'measurement'}: orientations=4 needs psi = 135 deg; got {got}"
        )
    return orientations


def _kes_rows(m: Measurement, orientations):
    """(orientations, ψ's, in-plane rows per orientation, incidence line θ_i + θ_r)."""
    orientations = select_orientations(m, orientations)
    psis = np.radians([0.0, 45.0, 90.0, 135.0][:orientations])
    in_plane = np.flatnonzero(m.is_in_plane)
    at = {k: in_plane[np.abs(m.psi[in_plane] - psi) < ORIENTATION_TOL] for k, psi in enumerate(psis)}
    if any(r.size == 0 for r in at.values()):
        raise MeasurementError(f"{m.source or 'measurement'}: KES needs in-plane samples at every orientation used")
    line_sum = incidence_line(m, np.concatenate(list(at.values())))
    return orientations, psis, at, line_sum


def incidence_line(m: Measurement, rows: np.ndarray) -> float:
    """The θ_i + θ_r line (radians) the KES table is built from.

    The paper's protocol keeps θ_i + θ_r = 90°.  Denser data sets (several θ_i per
    γ) are reduced to the line closest to 90° among those with at least half the
    samples of the most populated line; the choice is recorded and the other samples
    stay available for validation.
    """
    total = np.round(np.degrees(m.theta_i[rows] + m.theta_r[rows]), 6)
    values, counts = np.unique(total, return_counts=True)
    candidates = values[counts >= 0.5 * counts.max()]
    best = candidates[np.argmin(np.abs(candidates - 90.0))]
    return float(np.radians(best))


def _merge_close(values, tol: float = 1e-12) -> np.ndarray:
    """Sorted unique values, merging neighbours closer than ``tol`` (keeps the first)."""
    v = np.unique(values)
    keep = np.concatenate([[True], np.diff(v) > tol])
    return v[keep]


def line_weight(gamma, line_sum: float, normalisation: str = "sqrtcos") -> np.ndarray:
    """Foreshortening weight on the line θ_i + θ_r = S at deviation γ
    (:func:`kesbrdf.models.mappings.line_foreshortening`); ``sqrtcos``: √((cos γ + cos S)/2)."""
    return line_foreshortening(gamma, line_sum, normalisation)


def fit(
    m: Measurement,
    orientations: int | None = None,
    fallback: str = "log",
    body="auto",
    noise_floor="auto",
    interpolation: str = "kes",
    n_phi: int = DEFAULT_N_PHI,
    gamma_step=None,
    normalisation: str = "bounded",
    extrapolation: str = "fade",
    mapping: str = FIT_MAPPING,
) -> Model:
    """Build the extended-KES model from in-plane measurements.

    Parameters
    ----------
    m : Measurement
        Needs in-plane rows at ψ = 0, 45, 90° (and 135° for ``orientations=4``).
    orientations : {None, 3, 4}
        3 reproduces the paper's eq. 1–2; 4 (default when 135° was measured) uses
        all four orientations.
    fallback : {"log", "error"}
        What to do where K(φ) ≤ 0 between orientations (docs/method.md, "Interpolation over orientation"): interpolate log ρ
        there with a recorded warning (default), or raise :class:`KESError`.
    body : "auto", "lambertian", "none" or float
        The body term in 1/sr (module docstring): ``auto`` a Fresnel-like c g(μ_i) g(μ_r)
        when the samples show one, else Lambertian c of eq. B1 (``lambertian`` always).
    noise_floor : "auto" or float
        Floor of q (same unit as q: 1/sr).
    interpolation : {"kes", "nearest", "linear"}
        Interpolation over φ; the last two are baselines.
    n_phi : int
        Number of φ cells of the table (multiple of 8 keeps the measured azimuths on
        the grid).
    gamma_step : float, optional
        γ step of the table, radians (default: the measured spacing, at most 1°).
    normalisation : {"bounded", "sqrtcos"}
        Foreshortening weight w of q = (f − c)·w (:func:`kesbrdf.models.mappings.foreshortening`);
        ``sqrtcos`` is eq. 3 literally, whose lobe gains energy toward grazing incidence.
    extrapolation : {"fade", "hold"}
        The lobe beyond the last measured deviation (:data:`kesbrdf.models.mappings.EXTRAPOLATIONS`).
    mapping : {"halfvector", "deviation"}
        How a direction pair reads the table off the plane of incidence, recorded in
        ``parameters["mapping"]`` and used by every consumer not told otherwise
        (:attr:`Model.default_mapping`).  In the plane both give the same (φ, γ), so the
        table and the round trip do not depend on it.

    Returns
    -------
    Model
    """
    if fallback not in FALLBACKS:
        raise KESError(f"unknown fallback {fallback!r}; expected one of {', '.join(FALLBACKS)}")
    if interpolation not in INTERPOLATIONS:
        raise KESError(
            f"unknown interpolation {interpolation!r}; expected one of {', '.join(INTERPOLATIONS)}"
        )
    if not (isinstance(n_phi, (int, np.integer)) and not isinstance(n_phi, bool) and 0 < n_phi and n_phi % 8 == 0):
        raise KESError(f"expected n_phi to be a positive multiple of 8, got {n_phi!r}")
    if normalisation not in NORMALISATIONS:
        raise KESError(f"unknown normalisation {normalisation!r}; expected one of {', '.join(NORMALISATIONS)}")
    if extrapolation not in EXTRAPOLATIONS:
        raise KESError(f"unknown extrapolation {extrapolation!r}; expected one of {', '.join(EXTRAPOLATIONS)}")
    if mapping not in TABLE_MAPPINGS:
        raise KESError(f"unknown mapping {mapping!r} for a fit; expected one of {', '.join(TABLE_MAPPINGS)}")
    orientations, psis, at, line_sum = _kes_rows(m, orientations)
    C = m.n_channels

    # 1. half-samples per orientation on one incidence line θ_i + θ_r = S
    curves = {}  # slot -> (|γ| sorted, f values (n, C))
    used_rows = []
    for k in range(orientations):
        rows = at[k][np.abs(m.theta_i[at[k]] + m.theta_r[at[k]] - line_sum) < 1e-6]
        used_rows.append(rows)
        gamma = m.theta_r[rows] - m.theta_i[rows]
        for slot, sign in ((k, 1.0), (k + 4, -1.0)):
            sel = sign * gamma >= -1e-12
            if not np.any(sel):
                raise MeasurementError(
                    f"{m.source or 'measurement'}: orientation psi = {np.degrees(psis[k]):g} deg has no "
                    f"samples with {'gamma >= 0' if sign > 0 else 'gamma <= 0'} on the line "
                    f"theta_i + theta_r = {np.degrees(line_sum):g} deg"
                )
            g = np.abs(gamma[sel])
            order = np.argsort(g)
            curves[slot] = (g[order], m.values[rows[sel]][order])
    used = np.concatenate(used_rows)
    values_used = m.values[used]

    # 2. body term: the shared rule (kesbrdf.models.body): a Fresnel-like c g(μ_i) g(μ_r)
    #    when the samples show one (eq. B3-B5, body="auto"), else at most the darkest reading (B1)
    c, law, body_mode, law_report = body_term(body, values_used, m.wi[used], m.wr[used], C)

    # 3. q = f·√(cos θ_i cos θ_r) of every half-sample (body included: KES works on
    #    the measured quantity, as in the paper), floored at the noise level
    gamma_nodes = _merge_close(np.concatenate([curves[s][0] for s in curves]))
    slots = kes.half_slots(orientations)
    q_half_nodes = np.full((gamma_nodes.size, 8, C), np.nan)
    for slot in slots:
        g, f = curves[slot]
        q = f * line_weight(g, line_sum, normalisation)[:, None]
        for ch in range(C):
            q_half_nodes[:, slot, ch] = np.interp(gamma_nodes, g, q[:, ch])

    if isinstance(noise_floor, str) and noise_floor == "auto":
        peak = np.nanmax(q_half_nodes[:, slots, :], axis=(0, 1))
        floor = np.maximum(RELATIVE_NOISE_FLOOR * peak, np.finfo(float).tiny)
    else:
        floor = np.broadcast_to(np.asarray(noise_floor, float), (C,)).copy()
        if np.any(floor <= 0):
            raise KESError(f"expected a positive noise floor, got {noise_floor!r}")
    floored = []
    low = q_half_nodes[:, slots, :] < floor
    for gi, si, ch in np.argwhere(low):
        floored.append({
            "gamma_deg": round(float(np.degrees(gamma_nodes[gi])), 6),
            "azimuth_deg": round(float(np.degrees(kes.HALF_AZIMUTHS[slots[si]])), 6),
            "channel": m.channels[ch],
        })
    q_half_nodes[:, slots, :] = np.maximum(q_half_nodes[:, slots, :], floor)

    # 4. uniform γ grid containing the nodes
    gamma_grid = _gamma_grid(gamma_nodes, gamma_step)
    q_half = np.empty((gamma_grid.size, 8, C))
    for slot in slots:
        for ch in range(C):
            q_half[:, slot, ch] = np.interp(gamma_grid, gamma_nodes, q_half_nodes[:, slot, ch])
    if orientations == 3:
        q_half[:, [3, 7], :] = np.nan

    # 5. interpolate over φ at every γ, then split off the body: lobe = q − c·w(γ)
    phi_grid = np.arange(n_phi) * (2 * np.pi / n_phi)
    table, fallback_gamma = fill_table(q_half, phi_grid, gamma_grid, orientations, interpolation, fallback)
    body_q = c[None, None, :] * (line_weight(gamma_grid, line_sum, normalisation) * line_body_factor(law, gamma_grid, line_sum))[None, :, None]
    lobe = table - body_q
    clamped = int(np.count_nonzero(lobe < -1e-12 * np.abs(table)))
    table = np.maximum(lobe, 0.0)
    q_total_nodes = q_half_nodes
    q_half_nodes = q_half_nodes - c[None, None, :] * (line_weight(gamma_nodes, line_sum, normalisation)
                                                      * line_body_factor(law, gamma_nodes, line_sum))[:, None, None]

    fallback_deg = [round(float(np.degrees(gamma_grid[i])), 6) for i in fallback_gamma]
    diagnostics = {
        "warnings": [fallback_warning("gamma", fallback_deg)] if fallback_deg else [],
        "floored": floored,
        "noise_floor": floor.tolist(),
        "fallback_gamma_deg": fallback_deg,
        "unused_rows": int(len(m) - used.size),
        "incidence_line_deg": round(float(np.degrees(line_sum)), 6),
        "lobe_clamped": clamped,
        "gamma0_peaks": _gamma0_peaks(q_half_nodes, gamma_nodes, slots, m.channels),
    }
    if law_report is not None:
        diagnostics["body_law"] = law_report
    if orientations == 4:
        diagnostics["residual_135"] = _residual_135(q_total_nodes, m.channels)
    return Model(
        channels=tuple(m.channels),
        phi_grid=phi_grid,
        gamma_grid=gamma_grid,
        table=table,
        body=c,
        gamma_nodes=gamma_nodes,
        q_nodes=q_half_nodes,
        parameters={
            "orientations": orientations,
            "fallback": fallback,
            "body": body_mode if body_mode != "value" else c.tolist(),
            "noise_floor": noise_floor if isinstance(noise_floor, str) else floor.tolist(),
            "interpolation": interpolation,
            "gamma_interpolation": "linear",
            "n_phi": n_phi,
            "normalisation": normalisation,
            "extrapolation": extrapolation,
            "mapping": mapping,
        },
        diagnostics=diagnostics,
        input_info=m.input_info(),
        body_law=law,
    )


def _gamma_grid(nodes: np.ndarray, step) -> np.ndarray:
    gmax = float(nodes[-1])
    if gmax <= 0:
        raise MeasurementError("expected samples away from the mirror direction (|gamma| > 0), got only gamma = 0")
    if step is None:
        spacing = np.diff(nodes)
        uniform = spacing.size and np.allclose(spacing, spacing[0], rtol=1e-6, atol=1e-9) and np.isclose(nodes[0], 0.0, atol=1e-9)
        if uniform:
            step = spacing[0] / math.ceil(spacing[0] / MAX_GAMMA_STEP - 1e-9)
        else:
            step = math.radians(0.25)
    n = int(round(gmax / step))
    grid = np.linspace(0.0, n * step, n + 1)
    if grid[-1] < gmax - 1e-9:
        grid = np.append(grid, grid[-1] + step)
    return grid


def fill_table(q_half, phi_grid, gamma_grid, orientations, interpolation, fallback):
    """q(φ, γ) table, shape (n_phi, n_gamma, C), and the γ indices that fell back.

    ``q_half`` (n_gamma, 8, C): half-sample values per γ; K = 1/q is interpolated over
    φ (:mod:`kesbrdf.models.interpolation`), log q where K ≤ 0 and ``fallback="log"``.
    """
    slots = kes.half_slots(orientations)
    n_gamma, _, C = q_half.shape
    if interpolation == "nearest":
        az = kes.HALF_AZIMUTHS[slots]
        d = np.abs((phi_grid[:, None] - az[None, :] + np.pi) % (2 * np.pi) - np.pi)
        nearest = slots[np.argmin(d + 1e-9 * np.arange(slots.size), axis=1)]
        return np.transpose(q_half[:, nearest, :], (1, 0, 2)).copy(), []
    if interpolation == "linear":
        az = np.append(kes.HALF_AZIMUTHS[slots], 2 * np.pi)
        table = np.empty((phi_grid.size, n_gamma, C))
        for gi in range(n_gamma):
            for ch in range(C):
                vals = q_half[gi, slots, ch]
                table[:, gi, ch] = np.interp(phi_grid, az, np.append(vals, vals[0]))
        return table, []
    # KES on K = 1/q, vectorised over γ and channels
    K_half = 1.0 / q_half  # slots 3, 7 are NaN with 3 orientations and ignored
    K = kes.interpolate_circle(np.transpose(K_half, (0, 2, 1)), phi_grid, orientations)  # (γ, C, φ)
    # the KES form fails where K(φ) leaves the range it can represent: K ≤ 0 (ρ infinite or
    # negative) or K below 1/OVERSHOOT of the smallest measured K (ρ more than OVERSHOOT
    # times the brightest measured orientation at that γ, a spike of the interpolant)
    K_floor = np.nanmin(K_half[:, slots, :], axis=1) / OVERSHOOT  # (γ, C)
    bad = np.any(~(K > K_floor[:, :, None]), axis=2)  # (γ, C)
    fallback_gamma = []
    if bad.any():
        bad_gamma = np.flatnonzero(bad.any(axis=1))
        if fallback == "error":
            g = bad_gamma[0]
            raise KESError(
                f"K(phi) = 1/rho <= 0 (or rho > {OVERSHOOT:g}x the brightest orientation) between the measured orientations at gamma = "
                f"{math.degrees(gamma_grid[g]):.4g} deg ({bad_gamma.size} gamma value(s) affected): "
                "warp and weft differ too much for the KES form; use fallback='log' "
                "(the default; kesbrdf fit without --strict) to interpolate log rho there instead"
            )
        fallback_gamma = bad_gamma.tolist()
        q_log = kes.interpolate_circle_log(
            np.transpose(q_half[bad_gamma], (0, 2, 1)), phi_grid, orientations
        )  # (nb, C, φ)
        K[bad_gamma] = 1.0 / q_log
    table = np.transpose(1.0 / K, (2, 0, 1))
    return np.ascontiguousarray(table), fallback_gamma


def _gamma0_peaks(q_nodes, gamma_nodes, slots, channels):
    """The measured q at γ = 0 per orientation: the φ discontinuity at the mirror."""
    if not np.isclose(gamma_nodes[0], 0.0, atol=1e-9):
        return {}
    peaks = q_nodes[0, [s for s in slots if s < 4], :]
    return {
        "q_deg": {f"{int(round(np.degrees(kes.HALF_AZIMUTHS[s])))}": peaks[i].tolist() for i, s in enumerate([s for s in slots if s < 4])},
        "max_over_min": (peaks.max(axis=0) / np.maximum(peaks.min(axis=0), np.finfo(float).tiny)).tolist(),
        "channels": list(channels),
    }


def _residual_135(q_nodes, channels):
    """How far the measured 135° is from the 3-orientation prediction (= 45°).

    Computed on the measured q (body included, floored), relative to the 45° value.
    """
    q45 = q_nodes[:, [1, 5], :]
    q135 = q_nodes[:, [3, 7], :]
    rel = (q135 - q45) / np.maximum(np.abs(q45), np.finfo(float).tiny)
    return {
        ch: {
            "max_abs_rel": float(np.max(np.abs(rel[..., i]))),
            "rms_rel": float(np.sqrt(np.mean(rel[..., i] ** 2))),
        }
        for i, ch in enumerate(channels)
    }
