"""``kesbrdf.fit(measurement, kind="auto", **options)``: the one fitting entry point.

The CLI (``kesbrdf fit``), the viewer's upload and the demo all call :func:`fit`.
``kind="auto"`` picks the fitter that uses every row of the measurement, trying
:data:`kesbrdf.models.base.AUTO_CANDIDATES` in order (docs/models.md):

* the paper's protocol (one incidence line at ψ = 0, 45, 90, 135°) → ``kes``;
* several incidence angles per orientation → ``kes-halfdiff``; with ``compare`` (the
  default) and all four orientations in the plane, the dense rule then keeps
  ``fibre-coord`` when it predicts a held-out orientation better than interpolation over
  ψ and a held-out difference-angle band better than ``kes-halfdiff`` (eq. D2), else
  ``kes-halfdiff`` (:func:`_dense_rule`, docs/models.md);
* general (out-of-plane) geometries → ``scattered`` (a ``kes`` model fitted by least
  squares, with its sample-frame warp recorded).

When no candidate uses every row, the one that uses the most wins (the earlier on a
tie).  The subset rule (:func:`choose_fitter`, docs/models.md "More rows never predict
worse"): a candidate whose ``sparse_rows`` says the rows it would add are too sparse for
it (a few incidence angles beside the paper's line, a few out-of-plane samples) is passed
over for the candidate that fits the rest, so extra samples never make the fit worse
than the fit to the subset.  The library never prints: the choice, the reason, the rows used and the rows
not used (how many, and why) come back in a :class:`FitReport`, together with the
model's one-line warnings (e.g. the log fallback where K(φ) ≤ 0).

Options are passed to the chosen fitter; an option it does not accept is a one-line
:class:`~kesbrdf.errors.KesbrdfError` naming the kinds that do accept it.  ``strict``
(all kinds) turns the K(φ) ≤ 0 fallback back into an error (``fallback="error"``).
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass, field

import numpy as np

from kesbrdf.errors import KesbrdfError, MeasurementError
from kesbrdf.models.base import AUTO_CANDIDATES, fitter_class, known_fitters

__all__ = ["fit", "FitReport", "choose_fitter", "SUBSET_RULE"]


@dataclass
class FitReport:
    """What :func:`fit` did: the fitter chosen, why, and which rows it used.

    Attributes
    ----------
    kind : str
        Kind of the model built (``"kes"``, ``"kes-halfdiff"``, ...).
    fitter : str
        The fitter used (a kind's name, or ``"scattered"``).
    reason : str
        One line: why this fitter (``"asked for"`` when ``kind`` was given).
    rows_total, rows_used : int
    rows_unused : str
        One line: how many rows were not used and why ("" when all were used).
    candidates : dict
        Rows each candidate could use (``kind="auto"`` only).
    warnings : list of str
        The model's one-line warnings.
    comparison : dict or None
        ``kind="auto"`` on in-plane data: the leave-one-orientation-out comparison of the
        row-based choice with the woven-cloth prior (:func:`kesbrdf.validate.selection.loo_compare`):
        median NRMSE per candidate on the held-out biases and (prior, interpolation over
        ψ) on all four orientations, the mirror test of the biases, the candidate kept
        and why (:func:`kesbrdf.validate.selection.choose`); :meth:`comparison_summary` is the
        one-line form.
    """

    kind: str
    fitter: str
    reason: str
    rows_total: int
    rows_used: int
    rows_unused: str = ""
    candidates: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    comparison: dict | None = None

    def comparison_summary(self) -> str:
        """One line: the candidates' held-out errors, what was kept and why ("" when not compared)."""
        c = self.comparison
        if not c:
            return ""
        med = c.get("median_biases") or {}
        parts = ", ".join(f"{k} {v:.3f}" for k, v in sorted(med.items(), key=lambda kv: kv[1]))
        if "folds" in c:
            return f"{c['folds']}-fold log RMSE: {parts}; kept {c.get('kept')}"
        if not med and c.get("median_all"):  # the dense rule: all four orientations only
            four = ", ".join(f"{k} {v:.3f}" for k, v in c["median_all"].items())
            for side in ("most", "least"):  # the fibre-coord folds stopped early: a bound on its median
                if f"fibre_coord_median_at_{side}" in c:
                    four = f"fibre-coord at {side} {c[f'fibre_coord_median_at_{side}']:.3f}, " + four
            bands = c.get("bands")
            if bands:  # the second way (eq. D2): held out by difference angle
                at_least = "at least " if bands.get("skipped") else ""
                four += ("; held-out difference-angle bands, log SSE: "
                         + ", ".join(f"{k} {at_least if k == 'fibre-coord' else ''}{v:.4g}"
                                     for k, v in bands["log_sse"].items()))
            return f"leave-one-orientation-out NRMSE, median of the four orientations: {four}; kept {c.get('kept')}"
        text = f"leave-one-orientation-out NRMSE on the biases: {parts}"
        mirror = c.get("mirror") or {}
        if mirror.get("z") is not None:
            alike = "mirror images" if mirror.get("symmetric") else "not mirror images"
            text += f"; biases {alike} (z {mirror['z']:.2f}, limit {mirror.get('limit', float('nan')):g})"
        four = c.get("median_all") or {}
        if four:  # choose() applies the all-four test in every case: show its numbers
            text += "; all four orientations: " + ", ".join(f"{k} {v:.3f}" for k, v in four.items())
        why = f" ({c['why']})" if c.get("why") else ""
        return f"{text}; kept {c.get('kept')}{why}"

    def summary(self, after_comparison: bool = False) -> str:
        """One line for a terminal: kind, why, rows.  ``after_comparison``: the line follows
        :meth:`comparison_summary`, which already gives the comparison's reason; it is not
        repeated (``kesbrdf fit`` printed it twice)."""
        text = f"kind {self.kind}"
        if self.fitter != self.kind:
            text += f" ({self.fitter} fit)"
        reason = self.reason
        why = (self.comparison or {}).get("why")
        if after_comparison and why and f" ({why})" in reason:
            reason = reason.replace(f" ({why})", " (the comparison above)", 1)
        text += f": {reason}; uses {self.rows_used} of {self.rows_total} rows"
        if self.rows_unused:
            text += f"; not used: {self.rows_unused}"
        return text

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "fitter": self.fitter,
            "reason": self.reason,
            "rows_total": self.rows_total,
            "rows_used": self.rows_used,
            "rows_unused": self.rows_unused,
            "candidates": dict(self.candidates),
            "warnings": list(self.warnings),
            "comparison": self.comparison,
        }


#: The subset rule (docs/models.md, "More rows never predict worse"): a candidate whose
#: ``sparse_rows`` says the rows it would add are too sparse for it is passed over when
#: another candidate can fit the rest.  False restores the rule before it ("the kind
#: that uses every row"): for tests that show what the rule prevents, not for users.
SUBSET_RULE = True


def choose_fitter(measurement, candidates=None):
    """(name, mask, reason-for-unused, why, {name: rows usable}) of the automatic choice.

    The candidate that uses the most rows wins (the earlier on a tie), except that a
    fitter whose optional ``sparse_rows(measurement)`` gives a reason (the rows it could
    use beyond a simpler kind's are too sparse for it to use well) is passed over
    whenever another candidate can use some rows: that one then fits the subset it
    uses, and the rest are reported unused with the reason (:data:`SUBSET_RULE`).
    """
    m = measurement
    names = list(AUTO_CANDIDATES if candidates is None else candidates)
    n = len(m)
    best = None
    thin = None  # the best candidate set aside by sparse_rows
    counts = {}
    notes = {}
    for name in names:
        cls = fitter_class(name)
        skip = getattr(cls, "auto_skip", None)
        reason = skip(m) if skip is not None else None
        if reason:
            counts[name], notes[name] = 0, reason
            continue
        mask, why_not = cls.usable_rows(m)
        used = int(np.count_nonzero(mask))
        counts[name] = used
        notes[name] = why_not
        sparse = getattr(cls, "sparse_rows", None) if SUBSET_RULE and used else None
        too_thin = sparse(m) if sparse is not None else None
        if too_thin:
            if thin is None or used > thin[2]:
                thin = (name, mask, used, why_not, too_thin)
            continue
        if best is None or used > best[2]:
            best = (name, mask, used, why_not)
        if used == n and n > 0:
            break
    if (best is None or best[2] == 0) and thin is not None:
        best, thin = thin[:4], None  # nothing else can fit: the sparse candidate after all
    if best is None or best[2] == 0:
        detail = "; ".join(f"{k}: {v}" for k, v in notes.items())
        raise MeasurementError(f"{m.source or 'measurement'}: no model kind can use this measurement: {detail}")
    name, mask, used, why_not = best
    if thin is not None and thin[2] > used:
        why = (f"uses {used} of {n} rows; {thin[0]} could use {thin[2]} but {thin[4]}, and a fit to rows too "
               f"sparse for its kind predicts worse than this fit to the subset (more rows never predict worse)")
        why_not = f"{why_not}; {thin[0]}: {thin[4]}" if why_not else f"{thin[0]}: {thin[4]}"
    elif used == n:
        why = f"uses every row ({_protocol(name)})"
    else:
        others = ", ".join(f"{k} {v}" for k, v in counts.items() if k != name)
        why = f"uses the most rows ({used} of {n}; {others})"
    return name, mask, why_not, why, counts


def _protocol(name: str) -> str:
    return {
        "kes": "the paper's protocol: one incidence line per orientation",
        "kes-halfdiff": "several incidence angles per orientation",
        "scattered": "general geometries",
    }.get(name, name)


#: The prior's candidates in :func:`kesbrdf.validate.selection.loo_compare` and the options that build them.
PRIOR_CANDIDATES = {"prior": {"residual": False}, "prior+residual": {"residual": True}}


def fit(measurement, kind: str = "auto", strict: bool = False, compare: bool = True, parameter_prior=None, **options):
    """Fit a model to ``measurement``; returns ``(model, FitReport)``.

    Parameters
    ----------
    measurement : kesbrdf.measure.measurement.Measurement
    kind : str
        ``"auto"`` (module docstring) or a fitter name: ``"kes"``, ``"kes-halfdiff"``,
        ``"scattered"``, or any other in :data:`kesbrdf.models.base.FIT_MODULES`.
    strict : bool
        Make the K(φ) ≤ 0 log fallback an error (``fallback="error"``); only for the
        kinds that have that option.
    compare : bool
        ``kind="auto"`` only: when the row-based choice is ``kes`` and the woven-cloth
        prior (``fibre-prior``) can use every row too, compare them by
        leave-one-orientation-out validation on this measurement and keep prior +
        residual only where it beats every comparison the data allow
        (:func:`kesbrdf.validate.selection.choose`; ``FitReport.comparison``).  It costs a few prior fits (seconds); ``False``
        skips it, and so does any fit option (options belong to one kind).
    parameter_prior : None, "default", a JSON path or ParameterPrior
        The Gaussian prior over the woven-cloth prior's parameters (MAP fit,
        docs/prior.md §9), for every ``fibre-prior`` fit this call makes: the
        comparison's and the final one when the prior is kept.  With an explicit
        ``kind`` it is that kind's option.  None: the least-squares fit.
    **options
        Passed to the fitter; an option it does not accept is an error.

    Returns
    -------
    model : kesbrdf.models.base.ReflectanceModel
    report : FitReport

    >>> from kesbrdf.measure.gonio import measure
    >>> from kesbrdf.references.ward import AnisotropicWard
    >>> model, report = fit(measure(AnisotropicWard(0.2, 0.3), protocol="dense", step_deg=10), compare=False)
    >>> report.kind, report.rows_used == report.rows_total
    ('kes-halfdiff', True)
    """
    m = measurement
    if parameter_prior is not None:  # a prior, a file, or "default": the shipped prior
        from kesbrdf.models.parameter_prior import as_parameter_prior

        parameter_prior = as_parameter_prior(parameter_prior)
    if parameter_prior is not None and kind != "auto":
        options["parameter_prior"] = parameter_prior
    if kind == "auto":
        name, mask, why_not, why, counts = choose_fitter(m)
    else:
        if not isinstance(kind, str) or kind not in known_fitters():
            raise KesbrdfError(f"expected kind one of {', '.join(('auto',) + known_fitters())}, got {kind!r}")
        mask, why_not = fitter_class(kind).usable_rows(m)
        name, why, counts = kind, "asked for", {}
    comparison = None
    fitted = None
    # the fitter says how kind="auto" checks its choice against the prior (auto_compare)
    check = getattr(fitter_class(name), "auto_compare", None) if kind == "auto" and compare and not options \
        and not strict else None
    if check == "kfold":
        comparison = _kfold_with_prior(m)
        if comparison and comparison["kept"] == "fibre-prior":
            name = "fibre-prior"
            mask, why_not = fitter_class(name).usable_rows(m)
            why = f"fibre-prior beat the scattered KES fit in {comparison['folds']}-fold cross-validation on this data"
            if parameter_prior is not None:  # the folds were fitted without it (kfold_compare)
                options["parameter_prior"] = parameter_prior
    elif check == "loo":
        lines = mask
        comparison = _compare_with_prior(m, mask, parameter_prior)
        if comparison and comparison["kept"] in PRIOR_CANDIDATES:
            name = "fibre-prior"
            mask, why_not = fitter_class(name).usable_rows(m)
            options = dict(PRIOR_CANDIDATES[comparison["kept"]])
            if parameter_prior is not None:
                options["parameter_prior"] = parameter_prior
            why = f"{comparison['kept']} kept by leave-one-orientation-out validation on this data ({comparison['why']})"
            if comparison.get("compared_on"):
                why += f"; {comparison['compared_on']}"
                extras = _extras_check(m, lines, options)
                without = extras.pop("model")
                rows = extras.pop("rows")
                comparison["extras"] = extras
                if rows.all():
                    why += f"; {extras['why']}"
                elif not extras["used"]:  # the prior fitted to the incidence lines alone; the reason goes with the rows
                    fitted, mask, why_not = without, lines, extras["why"]
                else:  # some kinds of extras, not all
                    fitted = _fit_prior_on(m, rows, options)
                    mask, why_not = rows, extras["why"]
    elif check == "dense":
        comparison = _dense_rule(m)
        if comparison and "model" in comparison:  # fitted by the rule on every row (its variant fixed the folds')
            fitted = comparison.pop("model")
        if comparison and comparison["kept"] != name:
            name = comparison["kept"]
            mask, why_not = fitter_class(name).usable_rows(m)
            why = f"{name} kept by leave-one-orientation-out validation on this data ({comparison['why']})"
    cls = fitter_class(name)
    _check_options(name, cls, options, strict)
    if strict:
        options["fallback"] = "error"
    if fitted is None:
        model = cls.fit_measurement(m, **options)
        if hasattr(model, "remember_fit"):
            model.remember_fit(m, name, options)
    else:  # made on a subset by a check above (it remembers that subset)
        model = fitted
    used = int(np.count_nonzero(mask))
    unused = len(m) - used
    report = FitReport(
        kind=model.kind,
        fitter=name,
        reason=why,
        rows_total=len(m),
        rows_used=used,
        rows_unused=f"{unused} row(s): {why_not}" if unused else "",
        candidates=counts,
        warnings=list(getattr(model, "warnings", [])),
        comparison=comparison,
    )
    if parameter_prior is not None and "parameter_prior" not in options:
        report.warnings.append(f"parameter_prior not used: the model is {model.kind}, fitted without the fibre prior")
    if isinstance(model.diagnostics, dict):
        model.diagnostics["fit_report"] = report.to_dict()
    return model, report


def _kfold_with_prior(m) -> dict | None:
    """:func:`kesbrdf.validate.selection.kfold_compare` of the scattered fit and the prior."""
    try:
        prior_cls = fitter_class("fibre-prior")
    except (ImportError, KesbrdfError):
        return None
    mask, _ = prior_cls.usable_rows(m)
    if not mask.all():
        return None
    from kesbrdf.validate.selection import kfold_compare

    try:
        result = kfold_compare(m, ("scattered", "fibre-prior"))
    except KesbrdfError:
        return None
    result["kept"] = result["best"] or "scattered"
    result["median_biases"] = result["median"]  # one line for FitReport.comparison_summary
    return result


#: Comparisons already made, by the content of the rows compared (:func:`_rows_key`): the
#: decision is a function of those rows alone, so a second fit of the same rows, or of the
#: same incidence lines beside other extras (``kesbrdf plan`` scores many protocols that
#: share the paper's rows), reuses it instead of refitting four folds.  Bounded, oldest out.
_COMPARISONS: dict = {}
_COMPARISONS_MAX = 32


def _rows_key(m) -> str:
    """SHA-256 of everything :func:`kesbrdf.validate.selection.loo_compare` reads of ``m``
    (directions, ψ, values, uncertainty, channels and the frame the prior's axes follow)."""
    h = hashlib.sha256()
    for a in (m.theta_i, m.phi_i, m.theta_r, m.phi_r, m.psi, m.values, m.uncertainty):
        a = np.ascontiguousarray(np.asarray(a if a is not None else [], float))
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    h.update(repr(tuple(m.channels)).encode())
    h.update(str(m.metadata.get("frame", "")).encode())  # the prior's free axes for sample-frame data
    return h.hexdigest()


def _remember(key: str, result: dict) -> None:
    _COMPARISONS[key] = result
    while len(_COMPARISONS) > _COMPARISONS_MAX:
        _COMPARISONS.pop(next(iter(_COMPARISONS)))


def _compare_with_prior(m, rows=None, parameter_prior=None) -> dict | None:
    """:func:`kesbrdf.validate.selection.loo_compare` when the prior can use every row, with the
    candidate kept and why (:func:`kesbrdf.validate.selection.choose`).

    ``rows``: the rows the row-based choice (``kes``) fits.  When they are a subset (the
    paper's incidence lines beside extra samples the subset rule set aside: another
    incidence angle, a few out-of-plane pairs), the comparison runs on that subset, so
    the extras change nothing in the decision (docs/models.md, "More rows never predict
    worse"); a prior kept then fits every row, and the extras pin what the incidence
    line cannot (the θ_d law: the paper's line has θ_d = 45° everywhere).  Before, the
    leave-one-orientation-out comparison refused a measurement with extras and ``kes``
    was kept without one (issue 20: one extra incidence line made the default's
    hemispheres 0.18 → 0.60 on an Irawan silk).
    """
    try:
        prior_cls = fitter_class("fibre-prior")
    except (ImportError, KesbrdfError):  # the prior needs scipy (extra "fit")
        return None
    mask, _ = prior_cls.usable_rows(m)
    if not mask.all():
        return None
    from kesbrdf.validate.selection import loo_compare

    subset = rows is not None and not np.all(rows)
    compared = m.subset(rows) if subset else m
    key = _rows_key(compared) if parameter_prior is None else None
    if key is not None and key in _COMPARISONS:
        result = copy.deepcopy(_COMPARISONS[key])
    else:
        try:
            result = loo_compare(compared, decide=True,
                                 **({} if parameter_prior is None else {"parameter_prior": parameter_prior}))
        except KesbrdfError:  # too few orientations to hold one out: nothing to compare
            return None
        if key is not None:
            _remember(key, copy.deepcopy(result))
    from kesbrdf.validate.selection import choose

    result["kept"], result["why"] = choose(result)
    if subset:
        n = int(np.count_nonzero(rows))
        result["compared_on"] = f"compared on the {n} incidence-line rows"
    return result


def _fit_prior_on(m, rows, options):
    """The prior fitted to the rows ``rows`` of ``m`` (it remembers that subset)."""
    sub = m.subset(rows)
    model = fitter_class("fibre-prior").fit_measurement(sub, **options)
    model.remember_fit(sub, "fibre-prior", options)
    return model


def _extras_check(m, lines, options) -> dict:
    r"""Which extra rows a prior kept on the incidence lines should use: the extras rule's
    second half (docs/models.md, "Extras and the prior").

    The extras (rows beyond the ``lines`` the comparison was made on: another incidence
    angle, mirror samples, out-of-plane pairs) free what the lines cannot pin, the prior's
    θ_d law above all, and a freed law can extrapolate worse over the hemisphere than the
    law the lines hold (issue 20: an Irawan silk with a 60° line, hemispheres 0.18 → 0.46;
    the demo satin with 16 mirror samples, 0.79 → 1.56).  So each kind of extra
    (:func:`extras_kinds`) is held out, in groups g, two ways (:func:`extras_groups`): by
    orientation (the extras whose φ_i mod π is nearest one measured ψ) and by difference
    angle (quartiles of x = ωi·ωr among the extras).  Each group is predicted by the prior
    fitted to the lines and the other groups, and by the prior fitted to the lines alone;
    a kind is used when, for both ways,

    .. math:: \sum_g \sum_{k\in g} \bigl(\ln f_{\setminus g}(k) - \ln f_k\bigr)^2
              < m \sum_g \sum_{k\in g} \bigl(\ln f_\text{lines}(k) - \ln f_k\bigr)^2 ,  \quad (X1)

    m = :data:`EXTRAS_MARGIN`: the extras must cut the held-out error by a fifth both ways.
    A marginal preference is not evidence: the prior fits it rests on move with the last
    bit of the arithmetic, and on an AVX2-only machine the demo satin's 16 mirror samples
    passed (log SSE 9.05 and 7.02 against 10.07) where they had failed on the machine the
    rule was designed on, and predicted the hemispheres at 1.56 against the paper
    protocol's 0.76.

    Kinds that pass alone must pass together too, else only the one that helped most (the
    smallest worst-way ratio of the two sums) is used: two kinds can each help alone and
    mislead together (a silk's 60° line and its out-of-plane pairs: 0.44–0.48 against the
    paper protocol's 0.21, the line alone turned down).  Either way alone was wrong on one
    of twelve cases it was designed on (orientation folds miss a mirror peak that other
    orientations predict but the hemisphere does not share; θ_d folds miss a 60° line that
    fits its own θ_d but tilts the lobes).  Values are floored at 10⁻⁶ of the largest
    measured value before the log.  A kind with fewer than two groups either way cannot be
    held out and is not used.  More than :data:`MAX_EXTRA_KINDS` kinds are decided at once.
    Returns ``{"used", "rows" (N,) bool: the lines and the extras used, "kinds_used", "why",
    "log_sse": {kind: {way: {"with", "without"}}}, "groups", "model"}``, the model being the
    prior fitted to the lines.
    """
    cls = fitter_class("fibre-prior")
    lines = np.asarray(lines, bool)
    without = _fit_prior_on(m, lines, options)
    kinds = extras_kinds(m, ~lines)
    if len(kinds) > MAX_EXTRA_KINDS:  # too many to try one by one: all at once
        kinds = {"extra": ~lines}
    checks = {name: _held_out(m, lines, rows, options, without, cls) for name, rows in kinds.items()}
    passing = [name for name, c in checks.items() if c["used"]]
    rows = lines.copy()
    if len(passing) > 1:  # each kind helps alone; together they must pass the same test
        union = np.any([kinds[k] for k in passing], axis=0)
        checks["together"] = _held_out(m, lines, union, options, without, cls)
        if not checks["together"]["used"]:  # the kind that helped most, alone
            passing = [min(passing, key=lambda k: max(v["with"] / v["without"] for v in checks[k]["log_sse"].values()))]
    for name in passing:
        rows |= kinds[name]
    n_extra, n_used = int(np.count_nonzero(~lines)), int(np.count_nonzero(rows & ~lines))
    parts = "; ".join(f"{name} ({c['n']} rows): {c['why']}" for name, c in checks.items())
    if n_used == 0:
        why = f"the {n_extra} other rows are not used ({parts}); the prior fits the incidence lines alone"
    elif n_used == n_extra:
        why = f"the {n_extra} other rows are used ({parts})"
    else:
        why = (f"{n_used} of the {n_extra} other rows are used ({', '.join(passing)}; {parts}); "
               f"the other {n_extra - n_used} are not")
    return {"used": n_used > 0, "rows": rows, "kinds_used": passing, "why": why,
            "log_sse": {name: c["log_sse"] for name, c in checks.items()},
            "groups": {name: c["groups"] for name, c in checks.items()}, "model": without}


#: More kinds of extras than this are checked all at once (each kind costs up to nine fits).
MAX_EXTRA_KINDS = 4
#: Eq. (X1)'s margin m: the extras' held-out log SSE must be below m times the lines
#: alone's, both ways (docs/decisions.md, "Extras: a margin, not a preference").
EXTRAS_MARGIN = 0.8


def _held_out(m, lines, extras, options, without, cls) -> dict:
    """Eq. X1 for the rows ``extras`` beside ``lines``: both ways of holding them out."""
    sub = lines | extras
    ms, held_rows = m.subset(sub), extras[sub]
    groups = extras_groups(ms, held_rows)
    out = {"used": False, "n": int(np.count_nonzero(extras)), "log_sse": {},
           "groups": {way: len(set(g[held_rows])) for way, g in groups.items()}}
    thin = [way for way, k in out["groups"].items() if k < 2]
    if thin:
        out["why"] = f"at one {' and one '.join(thin)}, nothing holds them out: not used"
        return out
    from kesbrdf.validate.selection import LOG_FLOOR, log_sse

    floor = LOG_FLOOR * float(np.max(m.values))  # of the whole measurement, the same for every kind
    for way, label in groups.items():
        sse_with = sse_without = 0.0
        for g in np.unique(label[held_rows]):
            held = held_rows & (label == g)
            sse_with += log_sse(cls.fit_measurement(ms.subset(~held), **options).evaluate, ms, held, floor)
            sse_without += log_sse(without.evaluate, ms, held, floor)
        out["log_sse"][way] = {"with": sse_with, "without": sse_without}
        if not sse_with < EXTRAS_MARGIN * sse_without:
            break  # one way against is enough: the other need not be fitted
    out["used"] = len(out["log_sse"]) == len(groups) and all(v["with"] < EXTRAS_MARGIN * v["without"]
                                                             for v in out["log_sse"].values())
    scores = ", ".join(f"by {way} {v['with']:.3g} against {v['without']:.3g}" for way, v in out["log_sse"].items())
    out["why"] = f"{'used' if out['used'] else 'not used'}, held-out log SSE with them against the lines alone: {scores}"
    return out


def extras_kinds(m, extras) -> dict:
    """The kinds of extra rows :func:`_extras_check` decides one by one: each in-plane
    incidence line (an incidence angle θ_i with at least three viewing angles), the other
    in-plane rows (mirror samples and the like) together, and the out-of-plane rows."""
    inplane = m.is_in_plane
    ti = np.round(np.degrees(m.theta_i), 1)
    kinds = {}
    other = extras & inplane
    for t in np.unique(ti[other]):
        rows = other & (ti == t)
        if len(np.unique(np.round(m.theta_r[rows], 6))) >= 3:
            kinds[f"incidence line theta_i = {t:g} deg"] = rows
    if kinds:
        other = other & ~np.any(list(kinds.values()), axis=0)
    if other.any():
        kinds["other in-plane rows"] = other
    if np.any(extras & ~inplane):
        kinds["out-of-plane rows"] = extras & ~inplane
    return kinds


def extras_groups(m, extras) -> dict:
    """Labels (N,) of the two ways :func:`_extras_check` holds extras out: ``"orientation"``
    (index of the measured ψ nearest φ_i mod π) and ``"difference angle"`` (quartile of
    x = ωi·ωr among the extras' distinct values); rows outside ``extras`` get labels too."""
    from kesbrdf.validate.selection import difference_angle_bands

    psi = m.orientations()
    az = np.mod(m.phi_i, np.pi)
    gap = np.abs(np.mod(az[:, None] - psi[None, :] + np.pi / 2, np.pi) - np.pi / 2)
    return {"orientation": np.argmin(gap, axis=1), "difference angle": difference_angle_bands(m, extras)}


#: The kind the dense rule keeps when ``fibre-coord`` does not beat interpolation over ψ:
#: ``kes-halfdiff`` on every row.  Chosen leave one family out in benchmarks/bench_lofo.py
#: against ``kes`` on the dense data's incidence line (the paper's model on the paper's
#: slice at the dense grid's 6° step): 4 of 5 folds chose ``kes-halfdiff`` (fewest fabrics
#: with dense hemispheres above 1.1x the paper default's, then the lowest sum); ``kes`` on
#: the slice lost on the Ward lobes (1.11x and 1.39x the paper protocol's error: 6°
#: sampling misses narrow lobes).  Its known miss: the RGL felt, 1.45x (docs/decisions.md).
DENSE_KES_BRANCH = "kes-halfdiff"


def _dense_rule(m) -> dict | None:
    """The default for several incidence lines per orientation, all in the plane (the dense protocol).

    :func:`kesbrdf.validate.selection.dense_orientation_loo`: each of the four orientations is
    held out in turn and predicted by ``fibre-coord`` fitted to the other three and by
    interpolation over ψ.  When ``fibre-coord`` predicts the held-out orientations better
    (median of four), the rows are held out a second way, by difference angle
    (:func:`kesbrdf.validate.selection.dense_band_holdout`, eq. D2: four quartile bands of
    ωi·ωr, each predicted by ``fibre-coord`` and by :data:`DENSE_KES_BRANCH` fitted to the
    other three), which the orientations cannot test; :func:`kesbrdf.validate.selection.choose_dense`
    keeps ``fibre-coord`` only when both ways prefer it, else :data:`DENSE_KES_BRANCH`
    (the pattern of the extras check, eq. X1).  None when the four orientations are not
    all there.
    """
    if not np.all(m.is_in_plane):
        return None
    psi = np.degrees(m.psi)
    if not all(np.any(np.abs(psi - p) < 0.5) for p in (0.0, 45.0, 90.0, 135.0)):
        return None
    from kesbrdf.validate.selection import choose_dense, dense_band_holdout, dense_orientation_loo

    try:
        fitter_class("fibre-coord")
        result = dense_orientation_loo(m, decide=True)
    except (ImportError, KesbrdfError):
        return None
    if len(result["orientations"]) < 4:
        return None
    bands = None
    if choose_dense(result, DENSE_KES_BRANCH)[0] == "fibre-coord":  # the second way: by difference angle
        # the model kept if the bands agree, fitted first: its filament/staple variant is the folds'
        model = fitter_class("fibre-coord").fit_measurement(m)
        bands = result["bands"] = dense_band_holdout(m, DENSE_KES_BRANCH, decide=True,
                                                     kinds=tuple(model.prior.base.spec.kinds))
        if choose_dense(result, DENSE_KES_BRANCH, bands)[0] == "fibre-coord":
            model.remember_fit(m, "fibre-coord", {})
            result["model"] = model
    result["kept"], result["why"] = choose_dense(result, DENSE_KES_BRANCH, bands)
    result["median_biases"] = {}
    return result


def _check_options(name, cls, options, strict) -> None:
    accepted = set(cls.fit_options)
    unknown = sorted(set(options) - accepted)
    if strict:
        if "fallback" not in accepted:
            raise KesbrdfError(f"--strict (strict=True) does not apply to the {name!r} fit: it has no K(phi) fallback")
        if options.get("fallback", "error") != "error":
            raise KesbrdfError(f"strict=True contradicts fallback={options['fallback']!r}")
    if not unknown:
        return
    where_ok = {}
    for other in known_fitters():
        try:
            other_options = fitter_class(other).fit_options
        except ImportError:  # a fitter whose optional dependency is missing
            continue
        for opt in unknown:
            if opt in other_options:
                where_ok.setdefault(opt, []).append(other)
    parts = [
        f"{opt} (accepted by {', '.join(where_ok[opt])})" if opt in where_ok else f"{opt} (not an option of any kind)"
        for opt in unknown
    ]
    raise KesbrdfError(
        f"option(s) {', '.join(parts)} do not apply to kind {name!r}; it accepts {', '.join(cls.fit_options)}"
    )
