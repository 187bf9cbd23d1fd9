r"""A Gaussian prior over the fibre prior's parameters, for a MAP fit (docs/prior.md §9).

The paper protocol holds one in-plane slice (θ_d = 45°); the parameters that shape
reflection out of the plane of incidence are barely pinned by it.  A
:class:`ParameterPrior` holds, per parameter name θ_k of
:class:`kesbrdf.models.fibre_physics.PriorSpec`, a mean μ_k and a spread s_k learned
from fits of *other* fabrics to measurements that do pin them (:func:`learn_prior`);
:func:`kesbrdf.models.fibre_physics.fit_prior` (``parameter_prior=``) then minimises

.. math::

    \tfrac12\sum_n r_n(\theta)^2 + \tfrac12\,\lambda \sum_{k\in K} \frac{(\theta_k-\mu_k)^2}{s_k^2}   \qquad (M1)

(r_n the σ-weighted log residuals of the data, K the parameters the prior knows).
The staple twist enters as |ψ| (its sign is the variant's: the bounds of a staple start
fix it), so μ for ψ is taken with the sign of the variant's bounds.

Learning (eq. M2): for each name, the n values θ_k⁽ʲ⁾ of the training fits that have
it give the sample mean and variance; the variance is shrunk toward a wide
one, s_k² = (n v_k + n₀ w_k²)/(n + n₀) with w_k a quarter of the parameter's bound
range and n₀ = :data:`SHRINK_N0`, and floored at (:data:`MIN_SD_FRACTION` × range)².
Names present in fewer than :data:`MIN_FABRICS` fits are left out (no prior).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["ParameterPrior", "learn_prior", "load_prior", "as_parameter_prior", "DEFAULT_PRIOR_PATH", "GEOMETRY_SUFFIXES",
           "SHRINK_N0", "MIN_SD_FRACTION", "MIN_FABRICS"]

#: Parameters a prior is learned for: the yarn geometry and the θ_d law (not the colour
#: terms log_kd_c / log_ks_c, which are the fabric's own, nor the axis offset δ).
GEOMETRY_SUFFIXES = ("_u_lo", "_u_hi", "_log_s", "_c2", "_rho", "_psi")
THETA_D_NAMES = ("d1", "d2")
#: Every name a prior may hold: a yarn family's geometry and the θ_d law.
KNOWN_NAMES = frozenset(f"{fam}{suffix}" for fam in ("warp", "weft") for suffix in GEOMETRY_SUFFIXES) | set(THETA_D_NAMES)
#: Pseudo-count of the wide variance the learned one is shrunk toward (eq. M2).
SHRINK_N0 = 2.0
#: Floor of s_k as a fraction of the parameter's bound range (eq. M2).
MIN_SD_FRACTION = 0.02
#: Fewest training fits holding a parameter for it to get a prior.
MIN_FABRICS = 3
#: The prior shipped with the package (benchmarks/bench_map_prior.py --write).
DEFAULT_PRIOR_PATH = Path(__file__).resolve().parent.parent / "data" / "parameter_prior.json"
SCHEMA = "kesbrdf.parameter_prior/1"


def _range(name: str) -> tuple[float, float]:
    """Bound range of a parameter name (the twist as |ψ|), from PriorSpec.bounds."""
    from kesbrdf.models.fibre_physics import PriorSpec

    kinds = ("staple", "staple") if name.endswith("_psi") else ("filament", "filament")
    spec = PriorSpec(kinds, 1, False, name in THETA_D_NAMES)
    lo, hi = spec.bounds()
    i = spec.index()[name]
    return float(lo[i]), float(hi[i])


@dataclass
class ParameterPrior:
    """μ_k, s_k per parameter name and the weight λ of eq. (M1)."""

    mean: dict
    sd: dict
    weight: float = 1.0
    source: str = ""
    meta: dict = field(default_factory=dict)

    def with_weight(self, weight: float) -> "ParameterPrior":
        return ParameterPrior(dict(self.mean), dict(self.sd), float(weight), self.source, dict(self.meta))

    def without(self, names) -> "ParameterPrior":
        """The same prior without the parameters ``names`` (e.g. ("d1", "d2"))."""
        keep = [k for k in self.mean if k not in set(names)]
        return ParameterPrior({k: self.mean[k] for k in keep}, {k: self.sd[k] for k in keep}, self.weight,
                              self.source, dict(self.meta))

    def knows_theta_d(self) -> bool:
        return all(n in self.mean for n in THETA_D_NAMES)

    def terms(self, spec, bounds):
        """(cols, μ, w) for ``spec``: w = √λ/s_k; the twist's μ takes the sign of its bounds."""
        lo, hi = bounds
        cols, mu, w = [], [], []
        for i, name in enumerate(spec.names()):
            if name not in self.mean:
                continue
            m = float(self.mean[name])
            if name.endswith("_psi"):
                m = math.copysign(m, lo[i] + hi[i])
            cols.append(i)
            mu.append(min(max(m, lo[i]), hi[i]))
            w.append(math.sqrt(self.weight) / float(self.sd[name]))
        return np.array(cols, int), np.array(mu, float), np.array(w, float)

    def to_dict(self) -> dict:
        return {"schema": SCHEMA, "weight": self.weight,
                "parameters": {k: {"mean": float(self.mean[k]), "sd": float(self.sd[k])} for k in sorted(self.mean)},
                "meta": self.meta}

    @classmethod
    def from_dict(cls, doc: dict, source: str = "") -> "ParameterPrior":
        """Check and read :meth:`to_dict`'s document; every defect is one ModelError line."""
        from kesbrdf.errors import ModelError

        where = source or "parameter prior"
        if not isinstance(doc, dict):
            raise ModelError(f"{where}: expected a JSON object, got {type(doc).__name__}")
        if doc.get("schema") != SCHEMA:
            raise ModelError(f"{where}: expected schema {SCHEMA!r}, got {str(doc.get('schema'))[:60]!r}")
        pars = doc.get("parameters") or {}
        if not isinstance(pars, dict):
            raise ModelError(f"{where}: expected 'parameters' to be an object, got {type(pars).__name__}")
        mean, sd, bad = {}, {}, []
        for k, v in pars.items():
            try:
                m, s = float(v["mean"]), float(v["sd"])
            except (TypeError, KeyError, ValueError):
                bad.append(str(k)[:40])
                continue
            if k not in KNOWN_NAMES:
                raise ModelError(f"{where}: unknown parameter {str(k)[:40]!r}; expected names of the fibre prior's "
                                 f"geometry ({', '.join(sorted(KNOWN_NAMES))})")
            if not (math.isfinite(m) and math.isfinite(s) and s > 0):
                bad.append(str(k))
                continue
            a, b = _range(k)
            mean[k], sd[k] = m, max(s, MIN_SD_FRACTION * (b - a))  # the floor of learn_prior (eq. M2)
        try:
            weight = float(doc.get("weight", 1.0))
        except (TypeError, ValueError):
            weight = float("nan")
        if bad or not (math.isfinite(weight) and weight >= 0):
            raise ModelError(f"{where}: expected a finite mean and a positive sd per parameter and a weight >= 0, "
                             f"bad: {', '.join(bad) or 'weight'}")
        return cls(mean, sd, weight, source, dict(doc.get("meta") or {}) if isinstance(doc.get("meta"), dict) else {})


def learn_prior(fits, weight: float = 1.0, source: str = "", theta_d: bool = True) -> ParameterPrior:
    """Eq. (M2): μ_k, s_k of the geometry (and θ_d-law) parameters over ``fits``
    (:class:`kesbrdf.models.fibre_physics.FibrePrior` objects, each a fit of one fabric)."""
    fits = list(fits)
    values: dict = {}
    for fp in fits:
        for name, v in fp.parameters().items():
            if name.endswith(GEOMETRY_SUFFIXES) or (theta_d and name in THETA_D_NAMES):
                values.setdefault(name, []).append(abs(v) if name.endswith("_psi") else v)
    mean, sd = {}, {}
    for name, vals in sorted(values.items()):
        n = len(vals)
        if n < MIN_FABRICS:
            continue
        a, b = _range(name)  # the twist's range is that of |ψ| (positive bounds)
        wide = (b - a) / 4.0
        var = float(np.var(vals, ddof=1)) if n > 1 else 0.0
        s2 = (n * var + SHRINK_N0 * wide**2) / (n + SHRINK_N0)
        mean[name] = float(np.mean(vals))
        sd[name] = max(math.sqrt(s2), MIN_SD_FRACTION * (b - a))
    return ParameterPrior(mean, sd, float(weight), source,
                          {"n_fits": len(fits),
                           "counts": {k: len(v) for k, v in sorted(values.items())}})


def load_prior(path="default") -> ParameterPrior:
    """The prior of a JSON file (:meth:`ParameterPrior.to_dict`); ``"default"`` is the shipped one.
    A missing or unreadable file is one ModelError line."""
    from kesbrdf.errors import ModelError

    p = DEFAULT_PRIOR_PATH if path == "default" else Path(path)
    name = str(p.name if path == "default" else p)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ModelError(f"{name}: cannot read the parameter prior: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelError(f"{name}: expected a JSON parameter prior, got unreadable JSON ({str(exc)[:80]})") from None
    return ParameterPrior.from_dict(doc, name)


def as_parameter_prior(value):
    """``value`` as a :class:`ParameterPrior` or None: a prior, ``"default"`` (the shipped one),
    or the path of a JSON file; anything else is one ModelError line."""
    from kesbrdf.errors import ModelError

    if value is None or isinstance(value, ParameterPrior):
        return value
    if isinstance(value, (str, Path)):
        return load_prior(value)
    raise ModelError(f"parameter_prior: expected None, 'default', a JSON file or a ParameterPrior, "
                     f"got {type(value).__name__}")
