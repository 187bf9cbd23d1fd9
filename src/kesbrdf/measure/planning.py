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
allows, and stops when no group helps by more than :data:`MIN_GAIN`.  Pairs
(:func:`pair_candidates`) compete with single groups at every step: a group whose
samples share one difference angle (``specular:T``, ``oop:T``) cannot be held out alone
by ``kesbrdf.fit``'s extras check, so it is never used alone and never helps alone; two
of the same kind can be.

With a fitted model as the truth the planner can only tell how well each protocol pins
the model's own shape, not what the model got wrong: that needs a reference.

Carrying a plan out
-------------------
:meth:`PlanResult.to_dict` writes, for every protocol it scored and for the recommended
one, the rows :func:`simulate` measured (:func:`sample_table`: group, ψ, θ/φ of light and
viewer, wi, wr; :data:`SAMPLE_COLUMNS`), so the plan can be measured without Python;
:func:`geometry_from_table` reads them back for ``kesbrdf simulate --plan``, and
:func:`parse_groups` is the parser of ``kesbrdf simulate --extras`` (docs/planning.md,
"Carrying out a plan").
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
    "pair_candidates",
    "single_difference_angle",
    "PLAN_LIGHTS_DEG",
    "PROTOCOLS",
    "CANDIDATE_GROUPS",
    "group_geometry",
    "parse_groups",
    "protocol_samples",
    "sample_table",
    "geometry_from_table",
    "SAMPLE_COLUMNS",
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


def parse_groups(text: str, flag: str = "--extras") -> tuple[str, ...]:
    """``"line:30,oop:30"`` -> ``("line:30", "oop:30")``, each name checked by :func:`group_geometry`.

    The CLI's ``--extras`` goes through this parser, so it takes exactly the names a plan
    records; a bad one is a one-line error naming ``flag``, what was expected and what arrived.
    """
    names = tuple(part.strip() for part in str(text).split(","))
    if not names or any(not n for n in names):
        raise KesbrdfError(f"{flag}: expected comma-separated sample groups such as line:30,oop:30, got {text!r}")
    for name in names:
        try:
            group_geometry(name)
        except KesbrdfError as exc:
            raise KesbrdfError(f"{flag}: {exc}") from None
    return names


def _first_of_each(g: Geometry) -> np.ndarray:
    """Indices of ``g``'s rows, a geometry that repeats an earlier one left out (order kept)."""
    key = np.round(np.stack([g.theta_i, g.phi_i, g.theta_r, g.phi_r], axis=1), 9)
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


def _labelled(groups, base: Geometry | None = None, base_name: str = "base") -> tuple[Geometry, np.ndarray]:
    """The samples of ``base`` (if any) then of each group, shared ones kept once, with the
    name of the group each row comes from."""
    parts = ([base] if base is not None else []) + [group_geometry(name) for name in groups]
    names = ([base_name] if base is not None else []) + list(groups)
    g = Geometry.concat(parts)
    labels = np.concatenate([np.full(len(p), n, dtype=object) for p, n in zip(parts, names)])
    keep = _first_of_each(g)
    return Geometry(*(getattr(g, k)[keep] for k in ("theta_i", "phi_i", "theta_r", "phi_r", "psi"))), labels[keep]


def protocol_samples(groups, base: Geometry | None = None) -> Geometry:
    """The samples of a list of groups (after ``base``'s, when given), a sample shared by
    two groups kept once."""
    return _labelled(groups, base)[0]


def base_geometry(protocol: str = "paper", step_deg=None, orientations_deg=None) -> Geometry:
    """A gonio protocol (:func:`kesbrdf.measure.gonio.protocol_geometry`) as a :class:`Geometry`,
    the base ``kesbrdf simulate --extras`` adds groups to."""
    args = () if orientations_deg is None else (orientations_deg,)
    return _in_plane(*protocol_geometry(protocol, step_deg, *args))


#: Columns of a plan's sample tables (``plan.json``, docs/planning.md "Carrying out a plan").
#: Angles in degrees in the fabric frame of the measurement CSV (docs/formats.md); ψ is the
#: sample orientation of every row, the light at azimuth ψ + 180° (for an in-plane row the
#: CSV's ``psi_deg``, the viewer at azimuth ψ; an ``oop`` row has its viewer at ψ + 90°);
#: wi points toward the light, wr toward the viewer.
SAMPLE_COLUMNS = ("group", "psi_deg", "theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg",
                  "wi_x", "wi_y", "wi_z", "wr_x", "wr_y", "wr_z")


#: The conventions of :data:`SAMPLE_COLUMNS`, written into every plan.
SAMPLE_CONVENTIONS = (
    "degrees; fabric frame x = warp, y = weft, z = normal; azimuths phi from +x toward +y; wi points toward the "
    "light, wr toward the viewer (unit vectors); psi_deg = sample orientation: the light at azimuth psi + 180; "
    "in-plane rows (phi_i = phi_r + 180) are the measurement CSV's psi_deg,theta_i_deg,theta_r_deg with the viewer "
    "at azimuth psi; out-of-plane (oop) rows have the viewer at psi + 90; group = the sample group of the row"
)


def _clean(x: float, digits: int) -> float:
    """``x`` rounded to ``digits`` decimals, without a negative zero (87, not 87.00000000000001)."""
    return round(float(x), digits) + 0.0


def sample_table(groups) -> list[list]:
    """The rows of :data:`SAMPLE_COLUMNS` of a protocol: exactly the samples
    :func:`simulate` measures for ``groups``, in its order."""
    g, labels = _labelled(groups)
    wi = spherical_to_cartesian(g.theta_i, g.phi_i)
    wr = spherical_to_cartesian(g.theta_r, g.phi_r)
    psi = np.mod(g.phi_i - np.pi, 2 * np.pi)  # the light at ψ + 180°: ψ of in-plane rows, the orientation of oop rows
    rows = []
    for k in range(len(g)):
        angles = (psi[k], g.theta_i[k], g.phi_i[k], g.theta_r[k], g.phi_r[k])
        rows.append([str(labels[k]), *(_clean(math.degrees(a), 9) for a in angles),
                     *(_clean(v, 12) for v in wi[k]), *(_clean(v, 12) for v in wr[k])])
    return rows


def geometry_from_table(rows, columns=SAMPLE_COLUMNS, source: str = "plan") -> Geometry:
    """The :class:`Geometry` of a plan's sample table (the inverse of :func:`sample_table`).

    ψ of a row is kept only where the row lies in the plane of incidence (light opposite
    the viewer in azimuth, :func:`kesbrdf.io.measurement_csv.in_plane_psi`), as the
    measurement CSV reader does; an out-of-plane row has ψ NaN, as :func:`group_geometry`
    makes it.
    """
    from kesbrdf.io.measurement_csv import in_plane_psi

    need = ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")
    columns = list(columns)
    missing = [c for c in need if c not in columns]
    if missing:
        raise KesbrdfError(f"{source}: expected sample columns {', '.join(need)}, missing {', '.join(missing)}")
    if not isinstance(rows, list) or not rows:
        raise KesbrdfError(f"{source}: expected a non-empty list of sample rows, got {type(rows).__name__}")
    try:
        table = np.array([[float(r[columns.index(c)]) for c in need] for r in rows], float)
    except (TypeError, ValueError, IndexError):
        raise KesbrdfError(f"{source}: expected rows of {len(columns)} fields ({', '.join(columns)}) "
                           "with numeric angles") from None
    th_i, ph_i, th_r, ph_r = np.radians(table.T)
    bad = ~np.isfinite(table).all(axis=1) | (table[:, 0] < 0) | (table[:, 0] > 90) | (table[:, 2] < 0) | (table[:, 2] > 90)
    if bad.any():
        k = int(np.argmax(bad))
        raise KesbrdfError(f"{source}: sample {k + 1}: expected theta_i_deg and theta_r_deg in [0, 90], got "
                           f"{table[k, 0]:g} and {table[k, 2]:g}")
    ph_i, ph_r = np.mod(ph_i, 2 * np.pi), np.mod(ph_r, 2 * np.pi)
    psi = in_plane_psi(ph_i, ph_r)
    return Geometry(th_i, ph_i, th_r, ph_r, np.full(th_i.size, np.nan) if psi is None else psi)


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
        """The plan as JSON: the scores, and the sample geometries an operator measures.

        Every protocol within the budget gets ``"samples"`` (:func:`sample_table`: the rows
        the planner scored, in order), and ``"recommended"`` holds the last step of the
        greedy recommendation with its samples: what ``kesbrdf simulate --plan`` measures.
        """
        protocols = {name: ({**p, "samples": sample_table(p["groups"])} if not p.get("over_budget") else dict(p))
                     for name, p in self.protocols.items()}
        doc = {"budget": self.budget, "truths": self.truths, "protocols": protocols,
               "recommendation": self.recommendation, "lights_deg": [list(x) for x in PLAN_LIGHTS_DEG],
               "sample_columns": list(SAMPLE_COLUMNS), "sample_conventions": SAMPLE_CONVENTIONS}
        if self.recommendation:
            last = self.recommendation[-1]
            doc["recommended"] = {"groups": list(last["groups"]), "n_samples": last["n_samples"],
                                  "median": last["median"], "samples": sample_table(last["groups"])}
        return doc


def single_difference_angle(name: str) -> bool:
    """Whether every sample of group ``name`` has the same ω_i·ω_r (to 1e-9): such a group
    cannot be held out by difference angle, so ``kesbrdf.fit``'s extras check never uses
    it alone (docs/models.md, "Extra samples")."""
    g = group_geometry(name)
    wi = spherical_to_cartesian(g.theta_i, g.phi_i)
    wr = spherical_to_cartesian(g.theta_r, g.phi_r)
    dots = np.sum(wi * wr, axis=-1)
    return bool(np.ptp(dots) < 1e-9)


def pair_candidates(candidates) -> list[tuple[str, str]]:
    """Pairs of candidate groups worth trying together when no single one helps: both
    :func:`single_difference_angle`, of the same kind for the extras check (both in the
    plane of incidence, or both out of it), in candidate order.

    >>> pair_candidates(["specular:18", "line:30", "oop:30", "specular:36", "oop:60"])
    [('specular:18', 'specular:36'), ('oop:30', 'oop:60')]
    """
    single = [c for c in candidates if single_difference_angle(c)]
    kind = {c: bool(np.all(np.isnan(group_geometry(c).psi))) for c in single}
    return [(a, b) for i, a in enumerate(single) for b in single[i + 1:] if kind[a] == kind[b]]


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

    def best_of(options):
        """The option (a tuple of groups) that lowers the error most per sample, within budget."""
        best = None
        for option in options:
            extra = protocol_size(chosen + list(option)) - size
            if extra <= 0 or size + extra > budget:
                continue
            say(f"greedy step {len(result.recommendation)}: trying {' + '.join(option)}")
            err = expected_error(T, chosen + list(option), fit=fit, noise=noise)["median"]
            gain = (current - err) / extra
            if best is None or gain > best[0]:
                best = (gain, option, err, extra)
        # strictly below: at an error of 0 nothing helps (a group that changes nothing is not added)
        return best if best is not None and best[2] < current * (1.0 - MIN_GAIN) else None

    while remaining:
        best = best_of([(c,) for c in remaining] + pair_candidates(remaining))
        if best is None:
            break
        _, option, err, extra = best
        chosen += list(option)
        size += extra
        current = err
        for cand in option:
            remaining.remove(cand)
        result.recommendation.append({"add": " + ".join(option), "groups": list(chosen), "n_samples": size,
                                      "median": err})
    return result
