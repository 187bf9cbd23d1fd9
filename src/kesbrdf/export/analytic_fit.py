r"""Image-space least-squares fit of a standard analytic material to a kesbrdf model.

glTF, MaterialX, USD and apparel tools have no slot for a measured table, so their
exports carry the parameters of their own material model fitted to the kesbrdf BRDF.
One driver, :func:`fit_analytic`, fits any :class:`AnalyticMaterial` (``gltf_pbr``,
``openpbr``, ``standard_surface``, ``preview_surface``) and reports how far the fit is
from the model.

Sampling
    Directions are taken on a hemisphere grid with cells of equal solid angle:
    ``n_theta`` bands uniform in μ = cos θ (cell mid-points, so the horizon itself is
    never sampled) times ``n_phi`` azimuths.  The fit uses every pair of an incident
    grid and an outgoing grid (:data:`FIT_GRID`); the error is reported on a denser,
    different grid (:data:`ERROR_GRID`), so it is not the fit's own residual.

Objective (image space, :mod:`kesbrdf.export.image_space`)
    .. math:: r_{jc} = \sqrt{w_j}\,\bigl[d(\pi f^{fit}_{jc}\cos\theta_{i,j}) - d(\pi f^{ref}_{jc}\cos\theta_{i,j})\bigr],
              \quad d(x) = \mathrm{sRGB}(x/(1+x)),\quad w_j = \cos\theta_{r,j}\,L(\beta_j)

    i.e. the difference of the *displayed* pixel values of the two materials, each pair
    weighted by the image area that shows it (cos θ_r) and by a studio light
    distribution L over the light–viewer angle β; d is averaged over the studio
    exposure and three stops under it (``image_space.bracketed_value``), so a highlight
    the tone map squeezes near white still counts by its energy.  The tone map keeps the highlight in
    range and the sRGB curve keeps the body colour of a dark fabric visible, so both
    count as they do in a picture (a plain BRDF residual let the old fits drop a black
    satin's body colour to 10⁻³³ and raise its index to the bound, 5).
    ``scipy.optimize.least_squares`` (trust-region reflective, within the bounds) with a
    finite-difference Jacobian whose colour columns are grouped (``jac_sparsity``: a
    colour entry only moves its own channel), so a Jacobian costs one model evaluation
    per scalar parameter plus three.

Physical ranges
    Every parameter is bounded to its physical range (colours in [0, 1], indices in
    textile fibres' :data:`FIBRE_IOR_RANGE`, roughness in (0, 1]).  A parameter that
    ends at a bound is listed in ``error["at_bounds"]`` (``"ior max"``,
    ``"base_color[B] min"``), which the exports write into their files and the CLI
    prints; lower bounds that only switch a lobe off (no sheen, no anisotropy) are
    not listed (:attr:`ParamSpec.report_lo`).

Anisotropy rotation
    The rotation ρ of the anisotropy direction has two basins (the highlight stretched
    along the warp or along the weft, ρ ≈ 0 or π/2), which a local solver does not
    cross.  Both starts are fitted for :data:`SCOUT_NFEV` evaluations (bounds
    [−π/2, π/2] and [0, π]); the one with the lower cost is fitted to convergence.
    Both costs are reported.  ρ is returned in [0, π).

Error report (:attr:`AnalyticFit.error`)
    ``image_rmse``: the displayed difference at the studio exposure on the error grid,
    √(Σ w Δd² / Σ w), display units;
    ``nrmse``: RMS of (f^fit − f^ref)·cos θ_i divided by the RMS of f^ref·cos θ_i, both
    weighted by cos θ_r dω over the error grid and pooled over channels (BRDF space);
    ``nrmse_theta_le_70``: the same over pairs with θ_i, θ_r ≤ 70° (grazing pairs, where
    the KES model extrapolates as 1/√(cos θ_i cos θ_r), dominate the full NRMSE).
    ``rel_l1``: the weighted mean |difference| over the weighted mean reference.
    ``log_rmse``: RMS of log(1 + f cos θ_i) differences (the pre-2026-12 objective).
    ``worst``: the configurations with the largest |Δ(f_r cos θ_i)| (angles in degrees).
    ``at_bounds``: the parameters at a bound (above).

Caching
    :func:`fit_analytic` computes a fit once per model content, material and grids and
    keeps it in memory and on disk (:mod:`kesbrdf.export.fit_cache`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from typing import Callable, Protocol

import numpy as np

from kesbrdf.errors import KesbrdfError

__all__ = [
    "ParamSpec",
    "AnalyticMaterial",
    "AnalyticFit",
    "hemisphere_directions",
    "pair_grid",
    "target_function",
    "fit_analytic",
    "fit_analytic_uncached",
    "fit_error",
    "bounds_hit",
    "FIT_GRID",
    "ERROR_GRID",
    "FIBRE_IOR_RANGE",
]

#: (n_theta, n_phi) of the incident and outgoing grids used by the fit (14 400 pairs).
FIT_GRID = ((6, 12), (10, 20))
#: (n_theta, n_phi) of the incident and outgoing grids the error is reported on.
ERROR_GRID = ((12, 24), (16, 32))
#: Refractive index range of textile fibres (polypropylene 1.49, nylon 1.53, polyester
#: up to 1.72, cotton 1.53–1.58, silk 1.54–1.59; 1.3–1.8 with margin): every fitted
#: index stays inside, so F0 = ((η − 1)/(η + 1))² stays within 1.7–8.2 %.
FIBRE_IOR_RANGE = (1.3, 1.8)
#: solver evaluations spent in each anisotropy basin before the better one is continued
SCOUT_NFEV = 12
#: solver evaluations of the final fit (the trust region converges well before on the
#: references: docs/exports.md)
MAX_NFEV = 80
#: solver tolerances: scipy's default gtol (1e-8) stops an exact-family fit at an image
#: RMSE of ~1e-5 with a sheen of 2e-4 left over, so gtol and xtol are tighter; a real
#: fit stops when an iteration gains less than ftol (relative) of its cost
SOLVER_TOL = {"ftol": 1e-6, "xtol": 1e-10, "gtol": 1e-12}
#: a parameter within this fraction of its range from a bound is "at the bound"
BOUND_TOL = 1e-3
#: number of worst configurations reported.
N_WORST = 5
#: ``nrmse_theta_le_70`` restricts the NRMSE to pairs with both θ at most this (degrees).
CORE_THETA_DEG = 70.0
_CHANNEL_NAMES = ("R", "G", "B")


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: ``size`` is 1 or ``"color"`` (one value per channel).

    ``report_lo`` False: the lower bound only switches a lobe off (no sheen, no
    anisotropy), so ending there is not reported as a fit at its bound.  ``lobe``: the
    weight or colour parameter of the lobe this one shapes (a sheen's roughness); with
    that lobe off, this parameter means nothing and its bounds are not reported.
    """

    name: str
    lo: float
    hi: float
    start: float
    size: int | str = 1
    report_lo: bool = True
    lobe: str | None = None


class AnalyticMaterial(Protocol):
    """What :func:`fit_analytic` needs from a material model module."""

    name: str
    rotation: str | None  # name of the anisotropy-rotation parameter, or None

    def param_specs(self) -> list[ParamSpec]: ...

    def evaluate(self, p: dict, wi: np.ndarray, wr: np.ndarray, geo=None) -> np.ndarray: ...

    def rotation_basins(self) -> tuple[tuple[float, float, float], ...]: ...

    def canonical(self, p: dict) -> dict: ...


@dataclasses.dataclass
class AnalyticFit:
    """Result of :func:`fit_analytic`: parameters (JSON-ready) and the fit error.

    ``origin`` says where this instance came from: ``"fitted"``, or ``"memory"`` /
    ``"disk"`` for the fit cache (not part of :meth:`as_dict`).
    """

    material: str
    params: dict
    error: dict
    basins: list
    weighting: str
    grid: dict
    time_s: float
    channels: tuple
    origin: str = dataclasses.field(default="fitted", compare=False)

    @property
    def at_bounds(self) -> list[str]:
        return list(self.error.get("at_bounds", []))

    def summary(self) -> str:
        e = self.error
        bounds = f"; at bound: {', '.join(self.at_bounds)}" if self.at_bounds else ""
        return (
            f"{self.material} fit: image RMSE {e['image_rmse']:.3f} (display units), NRMSE {e['nrmse']:.3f}, "
            f"rel. L1 {e['rel_l1']:.3f} over the hemisphere (approximation of the kesbrdf model){bounds}"
        )

    def as_dict(self) -> dict:
        return {
            "material": self.material,
            "params": self.params,
            "error": self.error,
            "basins": self.basins,
            "weighting": self.weighting,
            "grid": self.grid,
            "time_s": self.time_s,
            "channels": list(self.channels),
        }

    @classmethod
    def from_dict(cls, d: dict, origin: str = "fitted") -> "AnalyticFit":
        return cls(
            material=d["material"], params=d["params"], error=d["error"], basins=d["basins"], weighting=d["weighting"],
            grid=d["grid"], time_s=float(d["time_s"]), channels=tuple(d["channels"]), origin=origin,
        )


WEIGHTING = (
    "least squares on displayed pixel values: sqrt(w) * [b(pi f_fit cos theta_i) - b(pi f_ref cos theta_i)], "
    "b(x) = (d(x) + d(x/8))/2, d(x) = sRGB(x/(1+x)), w = cos theta_r * L(beta) "
    "(studio light: dome + key 45 deg + rim 150 deg), "
    "equal-solid-angle hemisphere cells; parameters bounded to their physical ranges"
)


def hemisphere_directions(n_theta: int, n_phi: int) -> np.ndarray:
    """Unit directions at the centres of equal-solid-angle cells (uniform in cos θ and φ).

    Returns
    -------
    ndarray, shape (n_theta * n_phi, 3)
    """
    mu = (np.arange(n_theta) + 0.5) / n_theta
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - mu**2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), mu], -1).reshape(-1, 3)


def pair_grid(grid=FIT_GRID):
    """All (wi, wr) pairs of an incident and an outgoing hemisphere grid, shape (N, 3) each."""
    (ti, pi), (tr, pr) = grid
    wi = hemisphere_directions(ti, pi)
    wr = hemisphere_directions(tr, pr)
    return np.repeat(wi, wr.shape[0], axis=0), np.tile(wr, (wi.shape[0], 1))


def target_function(target) -> Callable:
    """A callable f(wi, wr) -> (N, C) for a kesbrdf model or any BRDF callable."""
    if callable(target) and not hasattr(target, "table") and not hasattr(target, "kind"):
        return target
    from kesbrdf.models.brdf import evaluate

    return lambda wi, wr: evaluate(target, wi, wr)


def _as_2d(values, n: int) -> np.ndarray:
    values = np.asarray(values, float)
    if values.ndim == 1:
        values = values[:, None]
    if values.shape[0] != n:
        raise KesbrdfError(f"analytic fit: expected the target to return {n} rows, got shape {values.shape}")
    return values


def _layout(specs: list[ParamSpec], n_channels: int):
    layout = []
    k = 0
    for s in specs:
        size = n_channels if s.size == "color" else int(s.size)
        layout.append((s, slice(k, k + size)))
        k += size
    return layout, k


def _unpack(x, layout) -> dict:
    return {s.name: (x[sl] if (sl.stop - sl.start) > 1 or s.size == "color" else x[sl.start]) for s, sl in layout}


def _jsonable(p: dict) -> dict:
    out = {}
    for k, v in p.items():
        v = np.asarray(v, float)
        out[k] = float(v) if v.ndim == 0 else [float(a) for a in v]
    return out


def bounds_hit(material: AnalyticMaterial, params: dict, tol: float = BOUND_TOL) -> list[str]:
    """Parameters of ``params`` at a bound of their range: ``["ior max", "base_color[B] min"]``.

    A colour with every channel at the same bound is one entry (``"specular_color max"``).
    The ranges are the material's ``report_specs()`` (the written parameters) when it
    has them, else its ``param_specs()``.  The anisotropy rotation (periodic) and lower
    bounds that switch a lobe off (:attr:`ParamSpec.report_lo` False) are not listed.
    """
    out = []
    specs = material.report_specs() if hasattr(material, "report_specs") else material.param_specs()
    for spec in specs:
        if spec.name == material.rotation or spec.name not in params:
            continue
        if spec.lobe is not None and spec.lobe in params and float(np.max(params[spec.lobe])) <= BOUND_TOL:
            continue  # the lobe is off: its shape parameters are arbitrary
        values = np.atleast_1d(np.asarray(params[spec.name], float))
        margin = tol * (spec.hi - spec.lo)
        hits = []
        for c, v in enumerate(values):
            label = spec.name if spec.size != "color" else f"{spec.name}[{_CHANNEL_NAMES[c] if values.size == 3 else c}]"
            if spec.report_lo and v <= spec.lo + margin:
                hits.append((label, "min"))
            elif v >= spec.hi - margin:
                hits.append((label, "max"))
        if len(values) > 1 and len(hits) == len(values) and len({b for _, b in hits}) == 1:
            hits = [(spec.name, hits[0][1])]  # every channel at the same bound: one entry
        out.extend(f"{label} {bound}" for label, bound in hits)
    return out


def fit_error(material: AnalyticMaterial, params: dict, f_ref: Callable, grid=ERROR_GRID) -> dict:
    """Image RMSE, NRMSE, relative L1, log-RMSE, worst configurations and bounds of a fit."""
    from kesbrdf.export.image_space import image_rmse
    from kesbrdf.export.microfacet import pair_geometry

    wi, wr = pair_grid(grid)
    ref = _as_2d(f_ref(wi, wr), wi.shape[0])
    p = {k: np.asarray(v, float) for k, v in params.items()}
    fit = _as_2d(material.evaluate(p, wi, wr, pair_geometry(wi, wr)), wi.shape[0])
    cos_i = wi[:, 2:3]
    w = wr[:, 2:3] * np.ones_like(ref)
    ok = np.isfinite(ref) & np.isfinite(fit)
    w = np.where(ok, w, 0.0)
    ref_c = np.where(ok, ref * cos_i, 0.0)
    fit_c = np.where(ok, fit * cos_i, 0.0)
    diff = fit_c - ref_c
    nrmse = math.sqrt(float(np.sum(w * diff**2)) / max(float(np.sum(w * ref_c**2)), 1e-300))
    rel_l1 = float(np.sum(w * np.abs(diff))) / max(float(np.sum(w * np.abs(ref_c))), 1e-300)
    # the same NRMSE away from grazing (θ_i, θ_r ≤ 70°), where the KES model does not extrapolate
    core = (np.minimum(wi[:, 2], wr[:, 2]) >= math.cos(math.radians(CORE_THETA_DEG)))[:, None]
    wc = w * core
    nrmse_core = math.sqrt(float(np.sum(wc * diff**2)) / max(float(np.sum(wc * ref_c**2)), 1e-300))
    log_res = np.log1p(np.maximum(fit_c, 0)) - np.log1p(np.maximum(ref_c, 0))
    log_rmse = math.sqrt(float(np.sum(w * log_res**2)) / max(float(np.sum(w)), 1e-300))
    worst_idx = np.argsort(-np.max(np.abs(diff), axis=1))[:N_WORST]
    worst = []
    for j in worst_idx:
        worst.append(
            {
                "theta_i_deg": round(math.degrees(math.acos(wi[j, 2])), 2),
                "phi_i_deg": round(math.degrees(math.atan2(wi[j, 1], wi[j, 0])) % 360, 2),
                "theta_r_deg": round(math.degrees(math.acos(wr[j, 2])), 2),
                "phi_r_deg": round(math.degrees(math.atan2(wr[j, 1], wr[j, 0])) % 360, 2),
                "f_ref": [float(a) for a in ref[j]],
                "f_fit": [float(a) for a in fit[j]],
            }
        )
    return {
        "image_rmse": image_rmse(fit, ref, wi, wr),
        "nrmse": nrmse,
        "nrmse_theta_le_70": nrmse_core,
        "rel_l1": rel_l1,
        "log_rmse": log_rmse,
        "max_abs_diff_f_cos": float(np.max(np.abs(diff))),
        "n_pairs": int(wi.shape[0]),
        "at_bounds": bounds_hit(material, params),
        "worst": worst,
        "definition": "NRMSE = RMS(d(f_r cos theta_i)) / RMS(f_ref cos theta_i), weights cos theta_r d omega, channels pooled",
        "image_definition": _image_definition(),
    }


def _image_definition() -> str:
    from kesbrdf.export.image_space import DEFINITION

    return DEFINITION


#: Fits of targets without content (plain callables): keyed by identity, held weakly.
_IDENTITY_CACHE: dict = {}
_IDENTITY_CACHE_SIZE = 8


def fit_analytic(material: AnalyticMaterial, target, grid=FIT_GRID, error_grid=ERROR_GRID, max_nfev: int = MAX_NFEV) -> AnalyticFit:
    """:func:`fit_analytic_uncached`, computed once per model content (:mod:`.fit_cache`).

    A kesbrdf model is looked up by the SHA-256 of its content, in memory and then in
    the on-disk cache; a new fit is stored in both.  Other callables are remembered
    by identity for the life of the object.  ``result.origin`` says which happened.
    """
    import weakref

    from kesbrdf.export import fit_cache

    digest = fit_cache.model_digest(target)
    if digest is not None:
        key = fit_cache.fit_key(digest, material.name, {"grid": grid, "error_grid": error_grid, "max_nfev": max_nfev})
        record, origin = fit_cache.lookup(key)
        if record is not None:
            return AnalyticFit.from_dict(record, origin=origin)
        result = fit_analytic_uncached(material, target, grid, error_grid, max_nfev)
        fit_cache.store(key, result.as_dict())
        return result
    key = (id(target), material.name, repr(grid), repr(error_grid), max_nfev)
    hit = _IDENTITY_CACHE.get(key)
    if hit is not None and hit[0]() is target:
        return dataclasses.replace(hit[1], origin="memory")
    result = fit_analytic_uncached(material, target, grid, error_grid, max_nfev)
    try:
        ref = weakref.ref(target)
    except TypeError:  # objects without weak references are not cached
        return result
    if len(_IDENTITY_CACHE) >= _IDENTITY_CACHE_SIZE:
        _IDENTITY_CACHE.pop(next(iter(_IDENTITY_CACHE)))
    _IDENTITY_CACHE[key] = (ref, result)
    return result


def _column_groups(material: AnalyticMaterial, layout, n_channels: int) -> list[list[tuple[int, int | None]]]:
    """Parameters whose finite differences share one evaluation: a colour's entries.

    Each group is a list of (parameter index, channel it moves or None for all).  A colour
    entry moves only its own channel's residuals, so the three entries of a colour are
    perturbed together; colours in ``material.coupled_colors`` (glTF's max over
    channels) and scalars get one evaluation each.
    """
    coupled = set(getattr(material, "coupled_colors", ()))
    groups = []
    for spec, sl in layout:
        idx = list(range(sl.start, sl.stop))
        if spec.size == "color" and n_channels > 1 and spec.name not in coupled:
            groups.append([(j, c) for c, j in enumerate(idx)])
        else:
            groups.extend([[(j, None)] for j in idx])
    return groups


class _Objective:
    """Residuals with the last evaluation remembered, and their grouped forward-difference Jacobian."""

    #: forward-difference step relative to max(1, |x|): √(double epsilon)
    STEP = 1.5e-8

    def __init__(self, residual, groups, n_pairs, n_channels, hi):
        self.residual, self.groups, self.hi = residual, groups, hi
        self.n_pairs, self.n_channels = n_pairs, n_channels
        self.last = None

    def fun(self, x):
        r = self.residual(x)
        self.last = (x.copy(), r)
        return r

    def jac(self, x):
        r0 = self.last[1] if self.last is not None and np.array_equal(self.last[0], x) else self.fun(x)
        J = np.zeros((r0.size, x.size))
        for group in self.groups:
            xp = x.copy()
            steps = []
            for j, _ in group:
                h = self.STEP * max(1.0, abs(x[j]))
                h = -h if x[j] + h > self.hi[j] else h  # step away from the upper bound
                xp[j] += h
                steps.append(h)
            d = self.residual(xp) - r0
            for (j, c), h in zip(group, steps):
                if c is None:
                    J[:, j] = d / h
                else:  # this entry moves only channel c
                    J[c :: self.n_channels, j] = d[c :: self.n_channels] / h
        return J


def _one_blas_thread():
    """Single-threaded BLAS for the solver's small vector products (threadpoolctl).

    The trust-region solver and LSMR do thousands of dot products of ~10⁵ numbers;
    OpenBLAS threads only add synchronisation there, and on a loaded machine they
    doubled the fits' CPU time.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with kesbrdf[export]
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def fit_analytic_uncached(
    material: AnalyticMaterial, target, grid=FIT_GRID, error_grid=ERROR_GRID, max_nfev: int = MAX_NFEV
) -> AnalyticFit:
    """Fit ``material``'s parameters to ``target`` (a kesbrdf model or f(wi, wr) callable).

    Parameters
    ----------
    material : AnalyticMaterial
        e.g. :data:`kesbrdf.export.gltf_pbr.GLTF_PBR`.
    target : Model or callable
        Evaluated on the fabric frame (x = warp, y = weft, z = normal), f_r in 1/sr.
    grid, error_grid : ((n_theta, n_phi), (n_theta, n_phi))
        Incident and outgoing hemisphere grids of the fit and of the error report.
    max_nfev : int
        Evaluation budget of the final solve (after :data:`SCOUT_NFEV` per basin).

    Returns
    -------
    AnalyticFit
    """
    from scipy.optimize import least_squares

    from kesbrdf.export.image_space import bracketed_value, pair_weight
    from kesbrdf.export.microfacet import pair_geometry

    t0 = time.perf_counter()
    f_ref = target_function(target)
    wi, wr = pair_grid(grid)
    ref = _as_2d(f_ref(wi, wr), wi.shape[0])
    n_pairs, n_channels = ref.shape
    if n_channels not in (1, 3):
        raise KesbrdfError(f"analytic fit: expected a model with 1 or 3 (RGB) channels, got {n_channels}")
    ok = np.isfinite(ref)
    ref = np.where(ok, ref, 0.0)
    geo = pair_geometry(wi, wr)
    radiance = math.pi * wi[:, 2:3]  # x = π f cos θ_i (image_space)
    w = pair_weight(wi, wr)[:, None] * ok
    sqrt_w = np.sqrt(w / max(float(np.sum(w)), 1e-300))
    d_ref = bracketed_value(ref * radiance)
    specs = material.param_specs()
    layout, n = _layout(specs, n_channels)

    def residual(x):
        f = material.evaluate(_unpack(x, layout), wi, wr, geo)
        f = np.where(np.isfinite(f), f, 0.0)
        return (sqrt_w * (bracketed_value(f * radiance) - d_ref)).ravel()

    groups = _column_groups(material, layout, n_channels)
    # initial values: diffuse-like colour from the median reflectance
    albedo = np.clip(np.pi * np.median(ref, axis=0), 0.02, 0.95)
    basins = material.rotation_basins() if material.rotation else ((None, None, None),)

    def solve(x0, lo, hi, nfev):
        obj = _Objective(residual, groups, n_pairs, n_channels, hi)
        return least_squares(obj.fun, np.clip(x0, lo, hi), jac=obj.jac, bounds=(lo, hi), max_nfev=nfev,
                             x_scale="jac", tr_solver="exact", **SOLVER_TOL)

    with _one_blas_thread():
        best, scouts = _solve_basins(material, layout, n, basins, albedo, solve, max_nfev)
    sol = best[1]
    params = _jsonable(material.canonical(_unpack(sol.x, layout)))
    error = fit_error(material, params, f_ref, error_grid)
    basin_report = [
        {"start_rotation": r[0], "cost": float(r[1].cost), "nfev": int(r[1].nfev), "continued": r is best} for r in scouts
    ]
    return AnalyticFit(
        material=material.name,
        params=params,
        error=error,
        basins=basin_report,
        weighting=WEIGHTING,
        grid={"fit": [list(g) for g in grid], "error": [list(g) for g in error_grid]},
        time_s=time.perf_counter() - t0,
        channels=("R", "G", "B") if n_channels == 3 else ("value",),
    )


def _solve_basins(material, layout, n, basins, albedo, solve, max_nfev):
    """Scout every rotation basin for :data:`SCOUT_NFEV` evaluations, continue the best."""
    scouts = []
    for start_rot, lo_rot, hi_rot in basins:
        x0, lo, hi = np.empty(n), np.empty(n), np.empty(n)
        for s, sl in layout:
            x0[sl], lo[sl], hi[sl] = s.start, s.lo, s.hi
            if s.name == material.rotation:
                x0[sl], lo[sl], hi[sl] = start_rot, lo_rot, hi_rot
            if s.size == "color" and s.name in getattr(material, "albedo_params", ()):
                x0[sl] = np.clip(albedo, s.lo, s.hi)
        sol = solve(x0, lo, hi, SCOUT_NFEV if len(basins) > 1 else max_nfev)
        scouts.append([start_rot, sol, lo, hi])
    best = min(scouts, key=lambda r: r[1].cost)
    if len(basins) > 1:
        best[1] = solve(best[1].x, best[2], best[3], max_nfev)
    return best, scouts
