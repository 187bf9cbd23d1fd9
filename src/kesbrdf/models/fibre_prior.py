r"""Model kind ``fibre-prior``: the woven-cloth prior times a KES-interpolated residual.

.. math::

    f_r(\omega_i,\omega_r) = f_\text{prior}(\omega_i,\omega_r)\cdot r(\omega_i,\omega_r)^{\tau(\gamma)}

* :math:`f_\text{prior}` is :class:`kesbrdf.models.fibre_physics.FibrePrior`, fitted to all usable rows;
* the residual ratio :math:`r = y / f_\text{prior}` is taken on the in-plane samples of
  the KES incidence line (θ_i + θ_r = 90° in the paper protocol) and interpolated over
  the deviation azimuth φ with the whole-circle extended KES form and linearly over γ,
  by the same code as the ``kes`` kind (:func:`kesbrdf.models.kes.fit` on the ratio, read
  back with :func:`kesbrdf.models.brdf.lookup` and divided by the line weight
  √((cos γ + cos S)/2), which the KES table carries);
* τ(γ) = 1 inside the measured γ range and falls smoothly (smoothstep) to 0 over
  :data:`RELAX_DEG` beyond it, so the residual relaxes to 1 where nothing was measured;
* g(ω) is the energy scale (docs/decisions.md, "Grazing energy of the fibre prior"):
  with a(θ) the largest directional albedo of f_prior·r^τ over light azimuths,
  g = min(1, :data:`ENERGY_BOUND`/a), tabulated at fit time over cos θ
  (:func:`energy_scale_table`; a few rounds, below) and read linearly
  (:func:`energy_scale`, which also reads tables over (cos θ, φ mod 180°)).  The model is

  .. math:: f_r = g(\omega_i)\,g(\omega_r)\,f_\text{prior}\,r^{\tau}

  so its albedo a'(ω_i) = g(ω_i)∫g(ω_r) f cos θ_r dω_r ≤ g(ω_i)·a(ω_i) ≤ ENERGY_BOUND
  (up to the table's interpolation), and g(ω_i)g(ω_r) is symmetric: reciprocal.  The
  residual is fitted to y/(g g f_prior), so measured samples are still reproduced; g
  depends on θ alone, so on the incidence line at any orientation g(θ_i)g(θ_r) is the
  factor the residual divided out at the measured ones (held-out orientations keep their
  values).  The refit gives back part of each scaling, so g is built in up to
  :data:`ENERGY_ROUNDS` rounds of (table, residual refit), each step raised to
  :data:`ENERGY_RELAX`.  Files without an ``energy`` table (written before) have g = 1.

With ``residual=False`` the model is the pure prior.  Every measured sample on the
KES line with y above the noise floor is reproduced to round-off (the ratio is
multiplied back exactly there).  Samples with y ≤ 0 cannot be reproduced by a
positive model: they are floored at ε = 10⁻⁴·max y before the ratio is taken.

:func:`kesbrdf.validate.selection.loo_compare` runs leave-one-orientation-out validation of this
kind against ``kes`` on the user's own data, for ``kind="auto"`` to use.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from kesbrdf.models.mappings import to_phi_gamma
from kesbrdf.errors import MeasurementError, ModelError
from kesbrdf.models.base import ReflectanceModel, register, check_fit_options
from kesbrdf.measure.measurement import Measurement
from kesbrdf.models.kes import line_weight
from kesbrdf.models.table import lookup
from kesbrdf.models.fibre_physics import THETA_D_ETA, FibrePrior, fit_prior
from kesbrdf.models.parameter_prior import as_parameter_prior
from kesbrdf.optics import fresnel_dielectric
from kesbrdf.models.support import (MAX_SIGMA_LOG, measured_support, support_distance,  # noqa: F401  (re-exported)
                                    support_distance_parts, theta_d as _theta_d)

__all__ = ["FibrePriorModel", "fit_residual", "residual_label", "bound_energy", "fit_kes_candidate", "RELAX_DEG", "ENERGY_BOUND", "energy_scale", "energy_scale_table", "OFF_SUPPORT_SCALE", "SIGMA_SCALES", "measured_support", "support_distance", "support_distance_parts", "misfit_level", "variance_parts", "off_support_variance", "ratio_measurement", "ratio_table", "predict_with_uncertainty", "calibration"]

#: Width of the relaxation of the residual toward 1 beyond the measured γ range.
RELAX_DEG = 15.0
#: Relative floor of the measured values before the ratio is taken.
RATIO_FLOOR = 1e-4
#: Largest directional albedo the energy scale g allows (module docstring): 1 less a
#: margin for the bilinear interpolation of g between its nodes (measured below 0.03 on
#: the 11 reference families, benchmarks/bench_energy.py).
ENERGY_BOUND = 0.95
#: Energy-scale nodes: cos θ uniform in [0, 1] (the node at cos θ = 0 is evaluated at
#: θ = ENERGY_THETA_MAX_DEG); the albedo is maximised over light azimuths φ uniform over
#: the half circle (the model is invariant under a half turn of both directions about
#: the normal).
ENERGY_N_COS, ENERGY_N_PHI = 17, 12
ENERGY_THETA_MAX_DEG = 89.99
#: Albedo quadrature of the table (:func:`kesbrdf.geometry.grazing_albedo` nodes):
#: g differs from (32, 64) nodes by < 6 % relative on the Sadeghi velvet fit, 4 s a table.
ENERGY_QUAD = (24, 48)
#: A first pass at (12, 24) nodes (1 s): below ENERGY_SKIP everywhere no table is made
#: (the coarse albedo differs from the fine one by well under the 0.15 gap to the bound).
ENERGY_SKIP_QUAD, ENERGY_SKIP = (12, 24), 0.8
#: Rounds of (albedo table, residual refit): each round scales down what the last still
#: lets exceed the bound.
ENERGY_ROUNDS = 4
#: Exponent of each round's scale: the refitted residual restores the measured samples and
#: with them about half of the scaling (velvet: 8.5, 1.32, 1.10, 1.02 × the bound in
#: successive rounds with exponent 1), so each step is squared to converge in two or three.
ENERGY_RELAX = 2.0


@register
class FibrePriorModel(ReflectanceModel):
    """The fibre prior with an optional KES residual (module docstring)."""

    kind = "fibre-prior"
    mappings = ("deviation",)
    #: The class of :attr:`prior` read back by :meth:`from_payload` (a subclass kind with
    #: another prior, e.g. ``fibre-coord``, names its own).
    prior_class = FibrePrior
    fit_options = ("residual", "kinds", "free_axes", "free_theta_d", "max_nfev", "parameter_prior")

    def __init__(self, prior: FibrePrior, residual=None, channels=("value",), parameters=None,
                 diagnostics=None, input_info=None, kes=None, support=None, energy=None):
        self.prior = prior
        #: Energy scale g over (cos θ, φ): SimpleNamespace(scale (n_cos, n_phi, C)), or
        #: None (g = 1, files written before it).
        self.energy = energy
        self.residual = residual  # SimpleNamespace(phi_grid, gamma_grid, table, line_sum, gamma_max) or None
        #: The KES table (``kes`` or ``kes-halfdiff`` kind) fitted to the same samples:
        #: the third candidate of the σ model term (docs/prior.md §5), or None.
        self.kes = kes
        #: Where the fit saw data: ``{"theta_d_deg": [lo, hi], "gamma_max_deg": g,
        #: "psi_deg": [measured orientations]}`` (:func:`measured_support`), for the
        #: off-support σ term; None in old files (``psi_deg`` may be empty in early ones).
        self.support = dict(support) if support is not None else None
        self.channels = tuple(channels)
        self.parameters = dict(parameters or {})
        self.diagnostics = dict(diagnostics or {})
        self.input_info = dict(input_info or {})

    # -- evaluation ---------------------------------------------------------------
    def residual_ratio(self, wi, wr) -> np.ndarray:
        """r(ωi, ωr)^τ(γ), shape (..., C); 1 everywhere for a pure prior."""
        wi, wr = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr, float))
        if self.residual is None:
            return np.ones(wi.shape[:-1] + (self.n_channels,))
        res = self.residual
        if getattr(res, "mode", "line") == "halfdiff":
            from kesbrdf.models.halfdiff import lookup_halfdiff, to_half_diff

            phi_h, theta_h, theta_d = to_half_diff(wi, wr)
            r = lookup_halfdiff(res, phi_h, theta_h, theta_d)
            x = np.clip((theta_h - res.theta_h_max) / math.radians(RELAX_DEG), 0.0, 1.0)
            tau = 1.0 - x * x * (3.0 - 2.0 * x)
            return np.exp(tau[..., None] * np.log(np.maximum(r, 1e-300)))
        phi, gamma = to_phi_gamma(wi, wr, "deviation")
        g_in = np.minimum(gamma, res.gamma_max)
        q = lookup(res, phi, g_in)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = q / line_weight(g_in, res.line_sum)[..., None]
        x = np.clip((gamma - res.gamma_max) / math.radians(RELAX_DEG), 0.0, 1.0)
        tau = 1.0 - x * x * (3.0 - 2.0 * x)
        return np.exp(tau[..., None] * np.log(np.maximum(r, 1e-300)))

    def evaluate_unit(self, wi, wr, mapping: str) -> np.ndarray:
        """Prior × residual ratio at unit rows above the horizon (the base class supplies
        normalisation, the horizon and NaN handling: :func:`kesbrdf.models.mappings.evaluate_pairs`)."""
        f = self.prior(wi, wr)
        if self.residual is not None:
            f = f * self.residual_ratio(wi, wr)
        if self.energy is not None:
            f = f * energy_scale(self.energy, wi) * energy_scale(self.energy, wr)
        return np.where(np.isfinite(f), f, 0.0)

    def scaled_prior(self, wi, wr) -> np.ndarray:
        """g(ωi)·g(ωr)·f_prior: the prior the residual is a ratio to."""
        f = self.prior(wi, wr)
        if self.energy is not None:
            f = f * energy_scale(self.energy, wi) * energy_scale(self.energy, wr)
        return f

    def __call__(self, wi, wr):
        return self.evaluate(wi, wr)

    # -- capabilities (kinds contract) -----------------------------------------------
    has_sigma = True

    def describe(self) -> str:
        chosen = self.parameters.get("prior")
        return (f"fibre-prior ({chosen or 'woven-cloth prior'}"
                f"{' x ' + residual_label(self.residual) if self.residual is not None else ', no residual'}), "
                f"channels {', '.join(self.channels)}")

    def predict_sigma(self, wi, wr):
        """``(f, σ, σ_ln f)`` (:func:`predict_with_uncertainty`, docs/prior.md §5)."""
        wi = np.asarray(wi, float).reshape(-1, 3)
        wr = np.asarray(wr, float).reshape(-1, 3)
        f, sigma, sigma_log = predict_with_uncertainty(self, wi, wr)
        f = np.where(np.isfinite(f), f, 0.0)
        sigma = np.where(np.isfinite(sigma), np.maximum(sigma, 0.0), 0.0)
        return f, sigma, sigma_log

    def render_plugin(self, mapping=None, extrapolation=None):
        """The ``kesbrdf_prior`` plugin; its extrapolation is its own residual's relaxation
        (``hold`` is its default and is not passed on); a KES ``mapping`` is an error."""
        if mapping not in (None, "deviation"):
            raise ModelError(f"mapping {mapping!r} applies to kes models only; a {self.kind} model has its own "
                             "parametrisation (drop --mapping)")
        props = {} if extrapolation in (None, "hold") else {"extrapolation": extrapolation}
        return "kesbrdf_prior", props

    def refit_options(self) -> dict:
        """This session's options, else the defaults (the file records what the fit found,
        e.g. whether a residual was fitted, not the options asked)."""
        memory = self.__dict__.get("_fit_memory")
        return dict(memory[2]) if memory is not None else {}

    # -- files --------------------------------------------------------------------
    def to_payload(self):
        fields = {"prior": self.prior.to_dict(), "has_residual": self.residual is not None}
        arrays = {}
        res = self.residual
        if res is not None and getattr(res, "mode", "line") == "halfdiff":
            fields["residual"] = {"mode": "halfdiff", "theta_h_max": float(res.theta_h_max)}
            arrays = {"residual_phi_grid": res.phi_grid, "residual_theta_h_grid": res.theta_h_grid,
                      "residual_theta_d_grid": res.theta_d_grid, "residual_table": res.table}
        elif res is not None:
            fields["residual"] = {"mode": "line", "line_sum": float(res.line_sum), "gamma_max": float(res.gamma_max)}
            arrays = {"residual_phi_grid": res.phi_grid, "residual_gamma_grid": res.gamma_grid,
                      "residual_table": res.table}
        fields["kes_candidate"] = None  # null: no KES table could be fitted (diagnostics say why)
        if self.kes is not None:
            from kesbrdf.io.model_file import model_to_dict

            doc = model_to_dict(self.kes)
            doc["diagnostics"], doc["input"] = {}, {}
            fields["kes_candidate"] = doc
        if self.support is not None:
            fields["support"] = self.support
        if self.energy is not None:
            fields["energy"] = {"bound": float(self.energy.bound), "cos_nodes": int(self.energy.scale.shape[0]),
                                "phi_nodes": int(self.energy.scale.shape[1])}
            arrays["energy_scale"] = self.energy.scale
        return fields, arrays

    @classmethod
    def from_payload(cls, fields, arrays, shared, source=None):
        try:
            prior = cls.prior_class.from_dict(fields["prior"])
            residual = None
            if fields.get("has_residual") and fields["residual"].get("mode") == "halfdiff":
                table = np.asarray(arrays["residual_table"], float)
                grids = [np.asarray(arrays[f"residual_{k}_grid"], float) for k in ("phi", "theta_h", "theta_d")]
                if table.shape[:3] != tuple(g.size for g in grids):
                    raise ModelError(f"{source or 'model'}: residual table shape {table.shape} does not match its grids")
                residual = SimpleNamespace(mode="halfdiff", phi_grid=grids[0], theta_h_grid=grids[1], theta_d_grid=grids[2],
                                           table=table, theta_h_max=float(fields["residual"]["theta_h_max"]))
            elif fields.get("has_residual"):
                table = np.asarray(arrays["residual_table"], float)
                phi, gamma = np.asarray(arrays["residual_phi_grid"]), np.asarray(arrays["residual_gamma_grid"])
                if table.shape[:2] != (phi.size, gamma.size):
                    raise ModelError(f"{source or 'model'}: residual table shape {table.shape} does not match grids ({phi.size}, {gamma.size})")
                residual = SimpleNamespace(phi_grid=phi, gamma_grid=gamma, table=table,
                                           line_sum=float(fields["residual"]["line_sum"]),
                                           gamma_max=float(fields["residual"]["gamma_max"]))
            if residual is not None:
                for name in ("table", "phi_grid", "theta_h_grid", "theta_d_grid", "gamma_grid"):
                    a = getattr(residual, name, None)
                    if a is not None and not np.all(np.isfinite(a)):
                        raise ModelError(f"{source or 'model'}: residual_{name}: expected finite values, got "
                                         f"{int(np.count_nonzero(~np.isfinite(a)))} NaN or inf")
            kes, support = None, None
            if fields.get("kes_candidate") is not None:
                from kesbrdf.io.model_file import model_from_dict

                kes = model_from_dict(fields["kes_candidate"], f"{source or 'model'}: kes_candidate")
            if fields.get("support") is not None:
                support = {"theta_d_deg": [float(v) for v in fields["support"]["theta_d_deg"]],
                           "gamma_max_deg": float(fields["support"]["gamma_max_deg"]),
                           "psi_deg": [float(v) for v in fields["support"].get("psi_deg", [])]}
                if len(support["theta_d_deg"]) != 2 or not all(map(math.isfinite, support["theta_d_deg"]
                                                                    + [support["gamma_max_deg"]] + support["psi_deg"])):
                    raise ModelError(f"{source or 'model'}: support: expected finite theta_d_deg [lo, hi], gamma_max_deg "
                                     f"and psi_deg, got {fields['support']!r}")
            energy = None
            if fields.get("energy") is not None:
                scale = np.asarray(arrays["energy_scale"], float)
                if scale.ndim != 3 or scale.shape[0] < 2 or scale.shape[1] < 1 or not np.all(np.isfinite(scale)) \
                        or np.any(scale < 0) or np.any(scale > 1):
                    raise ModelError(f"{source or 'model'}: energy_scale: expected a (cos, phi, channel) table of "
                                     f"values in [0, 1], got shape {scale.shape}")
                energy = SimpleNamespace(scale=scale, bound=float(fields["energy"]["bound"]))
        except ModelError:  # already names the file and the field (ModelError is a ValueError)
            raise
        except (KeyError, TypeError, ValueError, MeasurementError) as exc:
            raise ModelError(f"{source or 'model'}: bad fibre-prior payload ({exc})") from None
        diagnostics = dict(shared.get("diagnostics") or {})
        if "kes_candidate" not in fields or support is None:
            diagnostics["uncertainty"] = (
                "file written before the KES candidate and the measured support were stored: sigma = fit + spread "
                "to the pure prior + theta_d law only (overconfident off the measured slice, docs/prior.md section 5)")
        return cls(prior, residual, channels=shared.get("channels", ("value",)), parameters=shared.get("parameters"),
                   diagnostics=diagnostics, input_info=shared.get("input_info"), kes=kes, support=support,
                   energy=energy)

    # -- fitting ------------------------------------------------------------------
    @classmethod
    def usable_rows(cls, measurement):
        m = measurement
        ok = (m.theta_i < np.pi / 2) & (m.theta_r < np.pi / 2) & np.all(np.isfinite(m.values), axis=1)
        return ok, "needs finite values with both directions above the horizon"

    @classmethod
    def fit_measurement(cls, measurement, **options):
        check_fit_options(FibrePriorModel.kind, FibrePriorModel.fit_options, options)
        residual_opt = options.pop("residual", "auto")
        m = measurement
        rows, _ = cls.usable_rows(m)
        if options.get("parameter_prior") is not None:  # a prior, a file, or "default" (docs/prior.md §9)
            options["parameter_prior"] = as_parameter_prior(options["parameter_prior"])
        prior = fit_prior(m, rows=rows, **options)
        residual, note = None, "residual off"
        if residual_opt:
            try:
                residual = _fit_residual(prior, m.subset(rows))
                note = residual_label(residual, long=True)
            except MeasurementError as exc:
                if residual_opt is True:
                    raise
                note = f"no residual: {exc}"
        kes, kes_note = _fit_kes_candidate(m.subset(rows))
        model = cls(prior, residual, channels=m.channels, kes=kes, support=measured_support(m.subset(rows)),
                    parameters={"residual": residual is not None, "prior": prior.report.get("chosen"),
                                "theta_d_law": f"Fresnel eta={1.5} normalised at 45 deg"
                                + (" x exp(d1 x + d2 x^2)" if prior.spec.free_theta_d else "")
                                + (" with x = wi.wr held to [{:.3f}, {:.3f}]".format(*prior.spec.theta_d_range)
                                   if prior.spec.free_theta_d and prior.spec.theta_d_range else ""),
                                "energy": f"albedo-scaled, bound {ENERGY_BOUND}"},
                    diagnostics={"fit": prior.report, "residual": note, "kes_candidate": kes_note},
                    input_info=m.input_info())
        _bound_energy(model, m.subset(rows))
        return model


def _bound_energy(model: FibrePriorModel, m: Measurement) -> None:
    """Give ``model`` its energy scale g (module docstring), refitting the residual to the
    scaled prior after each round so the measured samples are still reproduced."""
    scale = None
    if np.all(energy_scale_table(model.evaluate, ENERGY_SKIP, ENERGY_SKIP_QUAD) >= 1.0):
        model.diagnostics["energy"] = "no scaling needed"
        return
    for _ in range(ENERGY_ROUNDS):
        new = energy_scale_table(model.evaluate)
        if np.all(new >= 1.0):
            break
        new = new ** ENERGY_RELAX  # over-relaxed: the residual refit gives back part of each step
        scale = new if scale is None else scale * new
        model.energy = SimpleNamespace(scale=scale, bound=ENERGY_BOUND)
        if model.residual is not None:
            model.residual = _fit_residual(model.scaled_prior, m)
    model.diagnostics["energy"] = ("no scaling needed" if scale is None else
                                   f"smallest energy scale g = {float(np.min(scale)):.3g}")


def _energy_nodes():
    mu = np.linspace(0.0, 1.0, ENERGY_N_COS)
    theta = np.degrees(np.arccos(mu))
    theta[0] = ENERGY_THETA_MAX_DEG
    phi = np.arange(ENERGY_N_PHI) * (180.0 / ENERGY_N_PHI)
    return theta, phi


def energy_scale_table(brdf, bound: float = ENERGY_BOUND, quad=None) -> np.ndarray:
    """min(1, bound/max_φ a(θ, φ)) at the cos θ nodes, shape (n_cos, 1, C): a is the
    directional albedo of ``brdf`` (:func:`kesbrdf.geometry.grazing_albedo`) at the
    light azimuths φ of :data:`ENERGY_N_PHI` nodes over the half circle."""
    from kesbrdf.geometry import grazing_albedo

    theta, phi = _energy_nodes()
    a = np.stack([grazing_albedo(brdf, theta, p, *(quad or ENERGY_QUAD)) for p in phi], axis=1)  # (n_cos, n_phi, C)
    return np.minimum(1.0, bound / np.maximum(a.max(axis=1, keepdims=True), 1e-300))


def energy_scale(energy, w) -> np.ndarray:
    """g(ω) of :func:`energy_scale_table`, bilinear in (cos θ, φ mod 180°), shape (..., C)."""
    scale = energy.scale
    n_mu, n_phi = scale.shape[:2]
    w = np.asarray(w, float)
    mu = np.clip(w[..., 2] / np.maximum(np.linalg.norm(w, axis=-1), 1e-300), 0.0, 1.0) * (n_mu - 1)
    i0 = np.minimum(np.floor(mu).astype(int), n_mu - 2)
    tm = (mu - i0)[..., None]
    ph = (np.arctan2(w[..., 1], w[..., 0]) % np.pi) * (n_phi / np.pi)
    j0 = np.floor(ph).astype(int) % n_phi
    j1 = (j0 + 1) % n_phi
    tp = (ph - np.floor(ph))[..., None]
    lo = scale[i0, j0] * (1 - tp) + scale[i0, j1] * tp
    hi = scale[i0 + 1, j0] * (1 - tp) + scale[i0 + 1, j1] * tp
    return lo * (1 - tm) + hi * tm


def _fit_kes_candidate(m: Measurement):
    """(KES model of the same samples, note): ``kes`` for one incidence line, ``kes-halfdiff``
    for several, None (and why) when neither can fit them.  It is the third candidate of
    the σ model term (:func:`predict_with_uncertainty`)."""
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.models.base import kind_class

    rm = m.subset(m.is_in_plane) if np.any(m.is_in_plane) else m
    name = "kes-halfdiff" if _incidence_lines(rm) > 1 else "kes"
    try:
        return kind_class(name).fit_measurement(m), f"{name} table of the same samples (sigma candidate)"
    except KesbrdfError as exc:
        return None, f"no KES candidate for sigma: {exc}"


def ratio_measurement(prior: FibrePrior, m: Measurement) -> Measurement:
    """In-plane rows of ``m`` with values y / f_prior (y floored at ε = RATIO_FLOOR·max y)."""
    if not np.any(m.is_in_plane):
        raise MeasurementError("the residual needs in-plane samples at psi = 0, 45, 90 deg; got none")
    inp = m.subset(m.is_in_plane)
    y = inp.values
    eps = RATIO_FLOOR * np.max(np.abs(y), axis=0)
    ratio = np.maximum(y, eps) / np.maximum(prior(inp.wi, inp.wr), 1e-300)
    return Measurement.in_plane(inp.psi, inp.theta_i, inp.theta_r, ratio, channels=inp.channels)


def ratio_table(rm: Measurement):
    """KES table of a ratio measurement (module docstring)."""
    from kesbrdf.models.kes import fit as kes_fit

    # the ratio is dimensionless and is not divided by any foreshortening at evaluation:
    # the line weight only passes through the table and is divided out again (sqrtcos)
    km = kes_fit(rm, body="none", fallback="log", noise_floor=1e-12, normalisation="sqrtcos")
    line_sum = math.radians(km.diagnostics["incidence_line_deg"])
    return SimpleNamespace(phi_grid=km.phi_grid, gamma_grid=km.gamma_grid, table=km.table,
                           line_sum=line_sum, gamma_max=float(km.gamma_grid[-1]))


def _incidence_lines(m: Measurement) -> int:
    """How many θ_i + θ_r lines hold at least 8 in-plane samples."""
    total = np.round(np.degrees(m.theta_i + m.theta_r)[m.is_in_plane], 6)
    _, counts = np.unique(total, return_counts=True)
    return int(np.count_nonzero(counts >= 8))


def _halfdiff_table(rm: Measurement):
    """(φ_h, θ_h, θ_d) table of a ratio measurement with several incidence lines."""
    from kesbrdf.models.halfdiff import fit_halfdiff, in_plane_half_diff

    hd = fit_halfdiff(rm, body="none", fallback="log", noise_floor=1e-12, normalisation="none")
    theta_h = in_plane_half_diff(rm.theta_i, rm.theta_r)[0]
    return SimpleNamespace(mode="halfdiff", phi_grid=hd.phi_grid, theta_h_grid=hd.theta_h_grid,
                           theta_d_grid=hd.theta_d_grid, table=hd.table, body=np.zeros(rm.n_channels),
                           theta_h_max=float(np.max(theta_h)))


def _fit_residual(prior: FibrePrior, m: Measurement):
    """The residual of ``prior`` on ``m``: the KES line table for one incidence line, the
    (φ_h, θ_h, θ_d) table (:mod:`kesbrdf.models.halfdiff`) for several; raises
    MeasurementError without KES orientations."""
    rm = ratio_measurement(prior, m)
    if _incidence_lines(rm) > 1:
        return _halfdiff_table(rm)
    return ratio_table(rm)


def residual_label(residual, long: bool = False) -> str:
    """What :func:`_fit_residual` built: the KES table of the incidence line, or the
    (φ_h, θ_h, θ_d) table of several lines (``long``: as the model's diagnostics say it)."""
    several = getattr(residual, "mode", "line") == "halfdiff"
    if long:
        return ("(phi_h, theta_h, theta_d) residual over several incidence lines" if several
                else "KES residual on the incidence line")
    return "half/difference residual" if several else "KES residual"


#: Public names of the fitting steps, for kinds built on this one (``fibre-coord``).
fit_residual = _fit_residual
bound_energy = _bound_energy
fit_kes_candidate = _fit_kes_candidate


#: Scale c of the earlier one-constant off-support term σ_off = c·d (eq. U2, σ of ln f
#: per radian), with the θ_d-law term: the σ before the misfit-scaled terms (eq. U1′),
#: kept for ``off_support_scale=`` and as the "before" of benchmarks/bench_calibrate_sigma.py.
#: Leave-one-family-out it left every family outside the coverage bands (docs/prior.md §5).
OFF_SUPPORT_SCALE = 0.60

#: Scales of the off-support terms of eq. (U1) (σ of ln f per radian of distance):
#: ``azimuth`` c_ψ multiplies s^q·d_ψ, q = ``azimuth_power`` (between the measured
#: orientations the residual is interpolated, and its error grows with how far the
#: prior is from the fabric, s); ``slice`` c₀ and ``slice_misfit`` c₁ give
#: (c₀ + c₁ s)·d_slice off the measured slice (θ_d outside its range, γ beyond it).
#: Provenance: benchmarks/bench_calibrate_sigma.py, fitted on all five reference families (Irawan–Marschner and Sadeghi presets, Ward,
#: Ashikhmin–Shirley, the RGL felt) at 2 % noise, paper protocol, held-out orientations
#: and both Fig. 6 hemispheres, to land within 1σ in 60–76 % and within 2σ in 90–98 %;
#: the leave-one-family-out fits and the coverage they give on the family left out are
#: in docs/prior.md §5 (2026-12-03).
SIGMA_SCALES = {"azimuth": 1.0, "azimuth_power": 0.75, "slice": 0.30, "slice_misfit": 3.0}


def predict_with_uncertainty(model: FibrePriorModel, wi, wr, others=(), off_support_scale=None, scales=None):
    r"""Prediction and a per-prediction σ: fit noise (Laplace) ⊕ model spread ⊕ off-support terms.

    .. math::

        \sigma_{\ln f}^2 = g^\top \Sigma_\theta\, g
            \;+\; \frac{1}{K}\sum_k (\ln f_k - \ln f)^2
            \;+\; (c_\psi\, s^q\, d_\psi)^2
            \;+\; \bigl((c_0 + c_1 s)\, d_\text{slice}\bigr)^2        \qquad (U1)

    * fit: g = ∂ ln f_prior/∂θ (:meth:`FibrePrior.log_jacobian`) and Σ_θ the Laplace
      covariance of the prior's fit;
    * model spread: the mean squared log difference between the prediction f (prior +
      residual, or the pure prior) and the other candidates f_k: the pure prior (when
      the model has a residual), the KES table fitted to the same samples (stored in
      the file, :attr:`FibrePriorModel.kes`) and every callable in ``others``;
    * s, the fabric's own misfit to the prior (:func:`misfit_level`, eq. U3: RMS of
      ln(f_KES/f_prior) on the measured slice), read from the file;
    * between orientations: d_ψ = sin θ_i times the light's azimuth gap to the nearest
      measured orientation ψ_k, mod 180° (:func:`support_distance_parts`); the residual
      that carries the fabric's departure from the prior is interpolated there, so the
      term grows with s (as s^q, q = ¾: the held-out errors of well-fitted fabrics sit
      near the noise, not in proportion to s);
    * off the measured slice: d_slice, θ_d outside the measured θ_d range and γ beyond
      the largest measured deviation; a floor c₀ (the prior's θ_d/γ extrapolation is
      never exact) plus c₁ s.

    c_ψ, q, c₀, c₁ are :data:`SIGMA_SCALES` (``scales`` overrides), chosen by
    leave-one-family-out calibration (docs/prior.md §5).  ``off_support_scale=c`` gives
    the earlier σ instead (eq. U1′: fit + spread + the θ_d-law term (w_s ln Φ(θ_d))² +
    (c·d)², d of :func:`support_distance`).

    Logs use ε = 10⁻⁴·max f so dark regions do not dominate.  A model read from a file
    written before the KES candidate and the support were stored lacks the spread to it
    and the off-support terms and keeps the θ_d-law term of eq. (U1′) (its diagnostics
    say so).

    Returns
    -------
    f : ndarray (N, C)
        The model's prediction, 1/sr.
    sigma : ndarray (N, C)
        σ in 1/sr (f·σ_ln f, the log-normal first-order width).
    sigma_log : ndarray (N, C)
        σ of ln f, capped at :data:`MAX_SIGMA_LOG`.
    """
    wi = np.asarray(wi, float).reshape(-1, 3)
    wr = np.asarray(wr, float).reshape(-1, 3)
    wi, wr = np.broadcast_arrays(wi, wr)
    f = model.evaluate(wi, wr)
    if off_support_scale is not None:
        var = _variance_terms(model, wi, wr, f, others)
        if model.support is not None:
            var = var + (off_support_scale * support_distance(model.support, wi, wr))[:, None] ** 2
    else:
        parts = variance_parts(model, wi, wr, f, others)
        var = parts["fit"] + parts["spread"]
        if model.support is not None:
            var = var + off_support_variance(model, wi, wr, scales)[:, None]
        else:  # files without the support: the θ_d-law term is their only off-slice growth
            var = var + parts["theta_d_law"]
    sigma_log = np.minimum(np.sqrt(np.maximum(var, 0)), MAX_SIGMA_LOG)
    return f, f * sigma_log, sigma_log


def off_support_variance(model: FibrePriorModel, wi, wr, scales=None) -> np.ndarray:
    """(c_ψ s^q d_ψ)² + ((c₀ + c₁ s) d_slice)² of eq. (U1), shape (N,)."""
    k = dict(SIGMA_SCALES, **(scales or {}))
    s = misfit_level(model)
    d_slice, d_psi = support_distance_parts(model.support, wi, wr)
    return (k["azimuth"] * s ** k["azimuth_power"] * d_psi) ** 2 + ((k["slice"] + k["slice_misfit"] * s) * d_slice) ** 2


def _variance_terms(model: FibrePriorModel, wi, wr, f, others=()):
    """Fit + spread + θ_d-law terms of eq. (U1′), shape (N, C) (the σ of files before the
    calibrated off-support term; :func:`variance_parts` gives them one by one)."""
    parts = variance_parts(model, wi, wr, f, others)
    return parts["fit"] + parts["spread"] + parts["theta_d_law"]


def variance_parts(model: FibrePriorModel, wi, wr, f, others=()) -> dict:
    """The terms of eq. (U1) that do not depend on the distance from the support, each
    of shape (N, C): ``fit`` (Laplace), ``spread`` (candidates) and ``theta_d_law``."""
    eps = max(float(np.nanmax(f)), 1e-300) * 1e-4
    fit = np.zeros_like(f)
    prior = model.prior
    above = (wi[:, 2] > 0) & (wr[:, 2] > 0)
    if prior.cov is not None and above.any():
        g = prior.log_jacobian(wi[above], wr[above])  # (n, C, P)
        fit[above] = np.einsum("ncp,pq,ncq->nc", g, prior.cov, g)
    spread = np.zeros_like(f)
    cands = list(others)
    if model.residual is not None:
        cands.append(prior)
    if model.kes is not None:
        cands.append(model.kes.evaluate)
    if cands:
        lf = np.log(f + eps)
        spread = np.mean([(np.log(np.maximum(np.asarray(c(wi, wr), float), 0) + eps) - lf) ** 2 for c in cands], axis=0)
    law = np.zeros_like(f)
    if not prior.spec.free_theta_d:
        # θ_d law not identified by the data (one θ_d slice): the spread between the
        # default Fresnel law and no θ_d dependence at all, on the specular fraction
        h = wi + wr
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        log_phi = np.log(np.maximum(fresnel_dielectric(np.sum(wi * h, axis=-1), THETA_D_ETA) / fresnel_dielectric(np.cos(np.pi / 4), THETA_D_ETA), 1e-300))
        fp = prior(wi, wr)
        kd = np.exp([prior.parameters()[f"log_kd_{c}"] for c in range(prior.spec.n_channels)])
        spec_frac = np.clip((fp - kd) / np.maximum(fp, 1e-300), 0.0, 1.0)
        law = (spec_frac * log_phi[:, None]) ** 2
    return {"fit": fit, "spread": spread, "theta_d_law": law}


def misfit_level(model: FibrePriorModel) -> float:
    r"""s: how far the fabric is from the prior, the RMS of ln(f_KES / f_prior) on the
    measured slice (eq. U3).

    The KES candidate reproduces the measured samples, so on the slice it stands for
    the data: s is the prior's own misfit to this fabric's measurement, read back from
    the model file (no extra field).  The slice is sampled at every measured orientation
    ψ_k, in the plane of incidence, at three θ_d across the measured range and θ_i every
    5° (θ_r = 2θ_d − θ_i, both within 0–85°); logs floor at ε = 10⁻⁴·max.
    0 without a KES candidate or a support (then σ has no misfit-scaled terms).
    """
    key = (id(model.kes), id(model.support))
    cached = model.__dict__.get("_misfit_level")
    if cached is not None and cached[0] == key:
        return cached[1]
    s = 0.0
    sup = model.support
    if model.kes is not None and sup is not None and sup.get("psi_deg"):
        lo, hi = sup["theta_d_deg"]
        wi, wr = [], []
        for psi in np.radians(sup["psi_deg"]):
            for td in np.radians(np.linspace(lo, hi, 3)):
                ti = np.radians(np.arange(0.0, 86.0, 5.0))
                tr = 2.0 * td - ti
                ok = (tr >= 0) & (tr <= np.radians(85.0))
                ti, tr = ti[ok], tr[ok]
                c, s_ = np.cos(psi), np.sin(psi)
                wi.append(np.stack([np.sin(ti) * c, np.sin(ti) * s_, np.cos(ti)], -1))
                wr.append(np.stack([-np.sin(tr) * c, -np.sin(tr) * s_, np.cos(tr)], -1))
        wi, wr = np.concatenate(wi), np.concatenate(wr)
        if wi.size:
            fk = np.maximum(np.asarray(model.kes.evaluate(wi, wr), float), 0)
            fp = np.maximum(np.asarray(model.scaled_prior(wi, wr), float), 0)
            eps = max(float(np.nanmax(fk)), 1e-300) * 1e-4
            r = np.log(fk + eps) - np.log(fp + eps)
            s = float(np.sqrt(np.nanmean(r**2))) if np.any(np.isfinite(r)) else 0.0
    model.__dict__["_misfit_level"] = (key, s)
    return s


def calibration(model: FibrePriorModel, reference, wi, wr, others=()) -> dict:
    """Fraction of reference truths within 1σ and 2σ of the prediction (log space)."""
    f, _, sl = predict_with_uncertainty(model, wi, wr, others)
    truth = np.asarray(reference(wi, wr), float)
    eps = max(float(np.max(truth)), 1e-300) * 1e-4
    z = np.abs(np.log(np.maximum(truth, 0) + eps) - np.log(f + eps)) / np.maximum(sl, 1e-12)
    return {"within_1sigma": float(np.mean(z <= 1)), "within_2sigma": float(np.mean(z <= 2)),
            "median_sigma_log": float(np.median(sl)), "n": int(z.size)}
