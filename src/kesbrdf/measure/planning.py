r"""Protocol planning: how much to measure, and which samples buy the most (issue 9).

The paper's protocol (θ_i + θ_r = 90°, four orientations, 116 samples) holds one slice
of the BRDF: the difference angle θ_d is 45° on every sample, so everything off that
slice is extrapolated by the model's assumptions.  Users deciding how much to measure
need the answer to one question: *for a fabric like mine, how wrong is the model over
the hemisphere if I measure this set of samples?*

This module answers it by simulation.  A *truth* (a reference BRDF, a fitted model
used as a surrogate, or a library of references) is measured with the virtual
gonioreflectometer in each candidate protocol, the default fit (:func:`kesbrdf.fit`
with ``kind="auto"``) builds a model from those samples, and the model is compared
with the truth on the viewing hemisphere for a set of lights (:data:`PLAN_LIGHTS_DEG`).
The expected error is the median over lights and truths of the hemisphere NRMSE

.. math:: \mathrm{NRMSE} = \frac{\sqrt{\langle (f_\mathrm{model} - f_\mathrm{true})^2\rangle}}{\langle |f_\mathrm{true}| \rangle}

(:func:`kesbrdf.validate.compare.metrics`), over the same (θ_r, φ_r) grid as Fig. 6.

Candidate sample groups (:func:`group_geometry`)
------------------------------------------------
``paper``        the paper's 116 samples (3° steps on θ_i + θ_r = 90°).
``specular:T``   θ_i = θ_r = T at the four orientations (4 samples): the mirror peak at
                 another difference angle θ_d = T, which is what pins the θ_d law.
``line:T``       an incidence line θ_i = T, θ_r = 0…84° in 6° steps (15 × 4 = 60 samples).
``oop:T``        out of plane: light at (T, ψ + π), viewer at (T, ψ + π/2) (4 samples).
``dense``        every (θ_i, θ_r) pair on a 6° grid (900 samples).

:func:`plan` reports every protocol of :data:`PROTOCOLS` within the budget, then
recommends additions to a base protocol by greedy selection: at each step it adds the
candidate group that lowers the expected error most per sample, while the budget
allows, and stops when no group helps by more than :data:`MIN_GAIN`.

With a fitted model as the truth the planner can only tell how well each protocol pins
the model's own shape, not what the model got wrong: that needs a reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from kesbrdf.errors import KesbrdfError
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import protocol_geometry
from kesbrdf.measure.measurement import Measurement
from kesbrdf.validate.compare import hemisphere_directions, metrics

__all__ = [
    "PLAN_LIGHTS_DEG",
    "PROTOCOLS",
    "CANDIDATE_GROUPS",
    "group_geometry",
    "simulate",
    "expected_error",
    "plan",
    "PlanResult",
]

#: Lights (θ_i, φ_i) in degrees over which the hemisphere error is taken: the paper's
#: Fig. 6 pair first, then near-normal, mid and grazing incidence along warp, bias, weft.
PLAN_LIGHTS_DEG = ((30.0, 90.0), (30.0, 45.0), (10.0, 0.0), (50.0, 0.0), (50.0, 90.0), (70.0, 45.0))

#: Hemisphere grid step (degrees) for planning: coarser than Fig. 6's 2.5° because every
#: candidate is fitted and evaluated many times; the NRMSE changes by < 2 % at 5°.
PLAN_GRID_STEP_DEG = 5.0

#: Named protocols reported by :func:`plan` (lists of sample groups).
PROTOCOLS: dict[str, tuple[str, ...]] = {
    "paper": ("paper",),
    "paper+specular": ("paper", "specular:18", "specular:36", "specular:60", "specular:72"),
    "paper+line30": ("paper", "line:30"),
    "paper+lines": ("paper", "line:30", "line:60"),
    "paper+out-of-plane": ("paper", "oop:30", "oop:60"),
    "dense": ("dense",),
}

#: Groups the greedy recommendation may add to the base protocol.
CANDIDATE_GROUPS = (
    "specular:18", "specular:36", "specular:60", "specular:72",
    "line:15", "line:30", "line:45", "line:60", "line:75",
    "oop:30", "oop:60",
)

#: Smallest relative error reduction (fraction of the current error) worth a group.
MIN_GAIN = 0.01

ORIENTATIONS_DEG = (0.0, 45.0, 90.0, 135.0)


@dataclass
class Geometry:
    """Sample directions of a group: angles in radians, ψ NaN for out-of-plane rows."""

    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    psi: np.ndarray

    def __len__(self) -> int:
        return self.theta_i.size

    @staticmethod
    def concat(parts) -> "Geometry":
        return Geometry(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("theta_i", "phi_i", "theta_r", "phi_r", "psi")))


def _in_plane(psi, theta_i, theta_r) -> Geometry:
    psi, theta_i, theta_r = np.broadcast_arrays(*(np.asarray(a, float) for a in (psi, theta_i, theta_r)))
    return Geometry(theta_i.ravel(), np.mod(psi + np.pi, 2 * np.pi).ravel(), theta_r.ravel(), psi.ravel().copy(), psi.ravel().copy())


def group_geometry(name: str) -> Geometry:
    """The samples of a named group (module docstring); a one-line error for unknown names."""
    psi = np.radians(ORIENTATIONS_DEG)
    if name in ("paper", "dense"):
        p, ti, tr = protocol_geometry(name)
        return _in_plane(p, ti, tr)
    kind, _, arg = name.partition(":")
    try:
        t = math.radians(float(arg))
    except ValueError:
        t = float("nan")
    if kind not in ("specular", "line", "oop") or not (0.0 <= t < math.pi / 2):
        raise KesbrdfError(
            f"sample group: expected paper, dense, specular:T, line:T or oop:T with 0 <= T < 90 deg, got {name!r}"
        )
    if kind == "specular":
        return _in_plane(psi, t, t)
    if kind == "line":
        tr = np.radians(np.arange(0.0, 90.0, 6.0))
        return _in_plane(psi[:, None], t, tr[None, :])
    n = psi.size
    return Geometry(np.full(n, t), np.mod(psi + np.pi, 2 * np.pi), np.full(n, t), np.mod(psi + np.pi / 2, 2 * np.pi), np.full(n, np.nan))


def protocol_samples(groups) -> Geometry:
    """The samples of a list of groups, a sample shared by two groups kept once."""
    g = Geometry.concat([group_geometry(name) for name in groups])
    key = np.round(np.stack([g.theta_i, g.phi_i, g.theta_r, g.phi_r], axis=1), 9)
    _, first = np.unique(key, axis=0, return_index=True)
    keep = np.sort(first)
    return Geometry(*(getattr(g, k)[keep] for k in ("theta_i", "phi_i", "theta_r", "phi_r", "psi")))


def protocol_size(groups) -> int:
    return len(protocol_samples(groups))


def simulate(truth, groups, noise: float = 0.0, rng=None) -> Measurement:
    """Measure ``truth`` (callable f(wi, wr) -> (..., C)) at the samples of ``groups``.

    Noise is relative Gaussian with standard deviation ``noise``·|f| (as
    :func:`kesbrdf.measure.gonio.measure`); duplicates across groups are kept once.
    """
    g = protocol_samples(groups)
    wi = spherical_to_cartesian(g.theta_i, g.phi_i)
    wr = spherical_to_cartesian(g.theta_r, g.phi_r)
    values = np.asarray(truth(wi, wr), float)
    if values.ndim == 1:
        values = values[:, None]
    unc = None
    if noise > 0:
        rng = np.random.default_rng(rng)
        unc = noise * np.abs(values)
        values = values + rng.normal(size=values.shape) * unc
    channels = tuple(getattr(truth, "channels", ())) or tuple(f"c{k}" for k in range(values.shape[1]))
    if len(channels) != values.shape[1]:
        channels = tuple(f"c{k}" for k in range(values.shape[1]))
    return Measurement(
        theta_i=g.theta_i, phi_i=g.phi_i, theta_r=g.theta_r, phi_r=g.phi_r,
        values=values, channels=channels, uncertainty=unc, psi=g.psi,
        metadata={"sample": "kesbrdf plan", "quantity": "brdf", "simulated": "true"},
    )


def default_fit(m: Measurement):
    """:func:`kesbrdf.fit` as ``kesbrdf fit`` runs it: the row-based choice (the subset rule of
    :func:`kesbrdf.fitting.choose_fitter`) and its comparison with the woven-cloth prior.

    The plan scores the model a user gets.  The comparison is made on the protocol's
    incidence lines alone (the extras rule, docs/models.md "Extras and the prior"), and
    every protocol of a plan shares the paper's rows and their noise draws, so
    :func:`kesbrdf.fit` makes it once per truth and reuses it for every other protocol
    (``kesbrdf.fitting._COMPARISONS``); a protocol then costs one fit of the kept kind
    (~0.1 s for ``kes``, 1–3 s for the prior).  Before, the planner fitted with
    ``compare=False`` for speed and scored ``kes`` where the default keeps the prior.
    """
    from kesbrdf.fitting import fit

    model, _report = fit(m)
    return model


def fitter(kind: str = "auto"):
    """The fit a plan scores: :func:`default_fit` for ``"auto"``, else ``kesbrdf.fit(m, kind=kind)``.

    ``kind="fibre-prior"`` plans for the woven-cloth prior (about 2–7 s of CPU a fit
    against ~0.1 s for KES, so a plan costs tens of seconds): the answer for users who
    will fit that kind, e.g. after ``kesbrdf fit`` kept it on their fabric.
    """
    from kesbrdf.models.base import known_fitters

    if kind == "auto":
        return default_fit
    if kind not in known_fitters():
        raise KesbrdfError(f"plan: expected kind one of {', '.join(('auto',) + known_fitters())}, got {kind!r}")

    def fit_kind(m: Measurement):
        from kesbrdf.fitting import fit

        return fit(m, kind=kind)[0]

    fit_kind.kind = kind
    return fit_kind


class _Truth:
    """A truth with its hemisphere values cached per light."""

    def __init__(self, name: str, brdf, lights_deg, step_deg: float):
        self.name, self.brdf = name, brdf
        wr, _, _ = hemisphere_directions(step_deg)
        self.wr = wr.reshape(-1, 3)
        self.lights = []
        for theta_i, phi_i in lights_deg:
            wi = spherical_to_cartesian(math.radians(theta_i), math.radians(phi_i))[None, :]
            self.lights.append(((theta_i, phi_i), wi, np.asarray(brdf(wi, self.wr), float)))


def _model_errors(model, truth: _Truth) -> list[float]:
    from kesbrdf.models.brdf import evaluate

    out = []
    for _, wi, f_true in truth.lights:
        pred = evaluate(model, wi, truth.wr)
        out.append(metrics(pred, f_true.reshape(pred.shape))["all"]["nrmse"])
    return out


def expected_error(truths, groups, fit=default_fit, noise: float = 0.0, seed: int = 0) -> dict:
    """Hemisphere NRMSE of the default fit from ``groups`` (module docstring).

    ``truths`` is a list of :class:`_Truth`.  Returns ``{"median", "per_truth":
    {name: {"median", "per_light"}}, "n_samples", "kinds", "rows_used"}``; a truth whose
    fit fails records its error message and counts as NRMSE 1.  ``rows_used`` is the
    fewest rows a fit used (its ``FitReport``): below ``n_samples`` the default fit left
    samples its kinds cannot use well (the subset rule, :func:`kesbrdf.fitting.choose_fitter`),
    so the protocol scores as the subset it did use.
    """
    per_truth, allv, kinds, used = {}, [], set(), []
    n = 0
    for k, t in enumerate(truths):
        m = simulate(t.brdf, groups, noise=noise, rng=seed + k)
        n = len(m)
        try:
            model = fit(m)
        except KesbrdfError as exc:
            per_truth[t.name] = {"median": 1.0, "error": str(exc)}
            allv.append(1.0)
            continue
        kinds.add(model.kind)
        report = (model.diagnostics or {}).get("fit_report") if isinstance(model.diagnostics, dict) else None
        used.append(int(report["rows_used"]) if report and "rows_used" in report else n)
        errs = _model_errors(model, t)
        per_truth[t.name] = {
            "median": float(np.median(errs)),
            "per_light": {f"{a:g},{b:g}": float(e) for ((a, b), _, _), e in zip(t.lights, errs)},
        }
        allv.append(float(np.median(errs)))
    return {"median": float(np.median(allv)), "per_truth": per_truth, "n_samples": n, "kinds": sorted(kinds),
            "rows_used": min(used) if used else 0}


@dataclass
class PlanResult:
    """What :func:`plan` found: the protocols and the greedy recommendation."""

    budget: int
    truths: list
    protocols: dict = field(default_factory=dict)
    recommendation: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"budget": self.budget, "truths": self.truths, "protocols": self.protocols,
                "recommendation": self.recommendation, "lights_deg": [list(x) for x in PLAN_LIGHTS_DEG]}


def plan(truths: dict, budget: int = 200, protocols=None, candidates=CANDIDATE_GROUPS, base=("paper",),
         fit=default_fit, noise: float = 0.0, lights_deg=PLAN_LIGHTS_DEG, step_deg: float = PLAN_GRID_STEP_DEG,
         progress=None) -> PlanResult:
    """Expected hemisphere error of candidate protocols, and the additions that buy the most.

    Parameters
    ----------
    truths : dict name -> callable f(wi, wr) -> (..., C)
        References (or fitted models wrapped as callables) to plan for; the expected
        error is the median over them.
    budget : int
        Largest number of samples a protocol may have.
    progress : callable(str) or None
        Called with a one-line message before each fit batch (the CLI prints it).
    """
    if not truths:
        raise KesbrdfError("plan: expected at least one reference or model to plan for, got none")
    if isinstance(budget, bool) or not isinstance(budget, (int, np.integer)) or budget < 1:
        raise KesbrdfError(f"plan: expected a positive integer budget of samples, got {budget!r}")
    protocols = PROTOCOLS if protocols is None else protocols
    T = [_Truth(name, brdf, lights_deg, step_deg) for name, brdf in truths.items()]
    result = PlanResult(budget=int(budget), truths=list(truths))
    say = progress or (lambda _msg: None)
    for name, groups in protocols.items():
        size = protocol_size(groups)
        if size > budget:
            result.protocols[name] = {"groups": list(groups), "n_samples": size, "over_budget": True}
            continue
        say(f"protocol {name} ({size} samples)")
        res = expected_error(T, groups, fit=fit, noise=noise)
        result.protocols[name] = {"groups": list(groups), "over_budget": False, **res}
    # greedy additions to the base protocol
    chosen = list(base)
    size = protocol_size(chosen)
    if size > budget:
        return result
    current = expected_error(T, chosen, fit=fit, noise=noise)["median"]
    result.recommendation.append({"add": None, "groups": list(chosen), "n_samples": size, "median": current})
    remaining = [c for c in candidates if c not in chosen]
    while remaining:
        best = None
        for cand in remaining:
            extra = protocol_size(chosen + [cand]) - size
            if extra <= 0 or size + extra > budget:
                continue
            say(f"greedy step {len(result.recommendation)}: trying {cand}")
            err = expected_error(T, chosen + [cand], fit=fit, noise=noise)["median"]
            gain = (current - err) / extra
            if best is None or gain > best[0]:
                best = (gain, cand, err, extra)
        if best is None or best[2] > current * (1.0 - MIN_GAIN):
            break
        _, cand, err, extra = best
        chosen.append(cand)
        size += extra
        current = err
        remaining.remove(cand)
        result.recommendation.append({"add": cand, "groups": list(chosen), "n_samples": size, "median": err})
    return result
