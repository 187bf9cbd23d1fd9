"""Leave-one-family-out calibration of the fibre-prior and kes σ, coverage before and after.

The σ is eq. U1 of :func:`kesbrdf.models.fibre_prior.predict_with_uncertainty`
(docs/prior.md §5); ``make bench`` runs this module (``run()``), a few minutes on one core.

For every reference of every family of benchmarks/bench_prior.py (Irawan–Marschner and
Sadeghi presets, Ward, Ashikhmin–Shirley, the RGL felt when Mitsuba imports), the
paper protocol is measured with 2 % noise (seeded), the ``fibre-prior`` kind is fitted
and saved/loaded through a model file (the σ users get), and three cases are scored:
the held-out orientations ψ = 15 … 165° (noise-free truth), and the Fig. 6 hemispheres
θ_i = 30°, φ_i = 90° and 45° (5° viewer grid).  cov_k is the fraction of truths within
kσ (log space), averaged over a family's references per case.

* after (eq. U1): σ² = fit + spread + (c_ψ s^q d_ψ)² + ((c₀ + c₁ s) d_slice)², s the
  fabric's misfit to the prior (:func:`misfit_level`).  (c_ψ, q, c₀, c₁) minimise, over a
  grid, the mean over families (each weighs the same) and cases of
  hinge(cov₁, 0.60, 0.76)² + hinge(cov₂, 0.90, 0.98)² + 0.05·((cov₁ − 0.683)² + (cov₂ − 0.954)²),
  the distance outside the target bands plus a small pull to the Gaussian values,
  among the parameters that keep every training reference's held-out orientations at
  ≥ 71 % within 2σ (``REF_FLOOR_2SIGMA``: the per-reference floor of
  tests/test_uncertainty.py, 70 %, plus 1 % so the test is not on its edge).
* before (eq. U1′): σ² = fit + spread + θ_d law + (c·d)², one constant c, scored the
  same way (the σ up to 2026-12-02, ``OFF_SUPPORT_SCALE``).

Leave-one-family-out: for each family the parameters are fitted on the other families
and the coverage on the left-out family is reported, before and after; then they are
fitted on all families (frozen in ``SIGMA_SCALES``).  Microflake/SGGX models are never
used.  The dense protocol's default kind (``fibre-coord``, same σ) is then scored with
the frozen scales, without fitting them (``dense_fibre_coord_frozen``).

σ of ``kes`` models (eq. K1 of :mod:`kesbrdf.models.kes_sigma`, docs/decisions.md "σ of kes
models"): the ``kes`` kind is fitted to the same measurement of every reference (saved
and loaded), and (a, q, b₀, b₁) of σ² = n² + (a s(γ)^q d_φ)² + ((b₀ + b₁ s̄) d_slice)²
are chosen on ``GRID_KES`` by the same objective and the same per-reference floor,
leave-one-family-out, then on all families (frozen in ``KES_SIGMA_SCALES``).  The floor
rules out 168 of the 1344 candidates on Irawan and on Sadeghi (their lowest held-out 2σ:
the polyester lining, 74 %, and the satins, 79–80 %, at the chosen point); without it the
same scales are chosen, on all families and in every fold (measured 2026-12-03).

The default model (``kesbrdf.fit``, kind "auto": ``kes`` or ``fibre-prior`` on the paper
protocol) of every reference is then scored per family left out (``default_lofo``):
before, only the fibre-prior references carry a σ (kes: none, counted in
``without_sigma_before``); after, the kes references carry eq. K1 with the scales fitted
without their family.  Both kinds' scales are the leave-one-family-out ones.

σ of ``kes-halfdiff`` models (``kes_halfdiff`` section; eq. K1 with the coordinates of
:mod:`kesbrdf.models.halfdiff_sigma`, docs/decisions.md "σ of kes-halfdiff models"): every
reference is measured with the dense protocol (6°, 2 % noise, same seed), the
``kes-halfdiff`` kind is fitted (saved and loaded), and the held-out orientations are
scored on the dense geometry (225 pairs each) with both hemispheres.  (a, q, b₀, b₁) are
chosen on ``GRID_HALFDIFF`` by the same objective and floor, leave-one-family-out, then
on all families (frozen in ``HALFDIFF_SIGMA_SCALES``); ``default_lofo`` gives the
coverage over the references whose default model on that measurement is kes-halfdiff.

Alone:  python benchmarks/bench_calibrate_sigma.py  (prints JSON);
        python benchmarks/bench_calibrate_sigma.py halfdiff  (the kes_halfdiff section only).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
for p in (str(HERE.parent / "src"), str(HERE)):
    if p not in sys.path:
        sys.path.insert(0, p)

from bench_prior import references  # noqa: E402

from kesbrdf.geometry import spherical_to_cartesian  # noqa: E402
from kesbrdf.measure.gonio import measure  # noqa: E402
from kesbrdf.io.model_file import load_model as load  # noqa: E402
from kesbrdf.models.base import kind_class  # noqa: E402
from kesbrdf.models.fibre_prior import (OFF_SUPPORT_SCALE, SIGMA_SCALES, FibrePriorModel,  # noqa: E402
                                         misfit_level, support_distance, support_distance_parts, variance_parts)
from kesbrdf.validate.compare import HELD_OUT_DEG, HEMISPHERE_LIGHTS_DEG, hemisphere_directions  # noqa: E402
from kesbrdf.validate.uncertainty import COVERAGE_BANDS  # noqa: E402
from kesbrdf.models.kes_sigma import KES_SIGMA_SCALES, combine, sigma_inputs  # noqa: E402
from kesbrdf.models.halfdiff_sigma import HALFDIFF_SIGMA_SCALES  # noqa: E402

NOISE = 0.02
SEED = 3
HEMI_STEP_DEG = 5.0
CASES = ("held_out", "hemi90", "hemi45")
#: Target bands of issue 20 (within 1σ, within 2σ) and the Gaussian values.
BAND1, BAND2 = COVERAGE_BANDS
TARGET = (0.683, 0.954)
#: Per-reference floor of within-2σ at held-out orientations on the training families.
REF_FLOOR_2SIGMA = 0.71
#: Largest σ of ln f (fibre_prior.MAX_SIGMA_LOG).
CAP = 3.0
#: Candidate c of the one-constant σ (before), log-spaced plus 0.
GRID_BEFORE = np.concatenate([[0.0], np.geomspace(0.01, 10.0, 121)])
#: Candidate (c_ψ, q, c₀, c₁) of eq. U1 (after).
GRID_AFTER = [(a, q, b, c) for a in (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0) for q in (0.5, 0.75, 1.0)
              for b in (0.0, 0.1, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5)
              for c in (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)]

#: Candidate (a, q, b₀, b₁) of eq. K1 (kes).
GRID_KES = [(a, q, b, c) for a in (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0) for q in (0.5, 1.0, 1.5)
            for b in (0.0, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5) for c in (0.0, 0.25, 0.5, 1.0, 1.5, 2.0, 3.0)]
KES_KEYS = ("azimuth", "azimuth_power", "slice", "slice_misfit")
#: Candidate (a, q, b₀, b₁) of eq. K1 for kes-halfdiff: a from 0.25 to 6, GRID_KES's q, and
#: b₀, b₁ to 4 and 6 (on GRID_KES the choice sat on its largest b₀ and b₁ and smallest a).
GRID_HALFDIFF = [(a, q, b, c) for a in (0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0) for q in (0.5, 1.0, 1.5)
                 for b in (0.0, 0.3, 0.75, 1.5, 2.0, 3.0, 4.0) for c in (0.0, 0.5, 1.0, 2.0, 3.0, 4.5, 6.0)]


def truth_sets(ref, protocol: str = "paper"):
    """[(case, wi, wr, truth)]: the held-out orientations (the ``protocol``'s geometry) and
    the two Fig. 6 hemispheres."""
    held = measure(ref, protocol=protocol, orientations_deg=HELD_OUT_DEG)
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    sets = [("held_out", held.wi, held.wr, held.values)]
    for (ti, pi), tag in zip(HEMISPHERE_LIGHTS_DEG, ("hemi90", "hemi45")):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(ti), np.radians(pi)), wr.shape)
        sets.append((tag, wi, wr, np.asarray(ref(wi, wr), float)))
    return [(tag, *np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr_, float)), truth)
            for tag, wi, wr_, truth in sets]


def log_error(f, truth) -> np.ndarray:
    """|ln(t + ε) − ln(f + ε)|, ε = 10⁻⁴·max t."""
    eps = max(float(np.max(truth)), 1e-300) * 1e-4
    return np.abs(np.log(np.maximum(truth, 0) + eps) - np.log(np.maximum(f, 0) + eps))


def table_cases(ref, tmp: Path, kind: str = "kes", protocol: str = "paper", default: bool = True) -> dict:
    """{case: ingredients of eq. K1} of the ``kind`` table (``kes`` or ``kes-halfdiff``)
    fitted to the ``protocol`` measurement (the one of :func:`cases`), through its model
    file, plus ``"default"``: the kind ``kesbrdf.fit`` keeps on that measurement (when
    ``default``)."""
    import kesbrdf

    m = measure(ref, protocol=protocol, noise=NOISE, noise_floor=1e-4, rng=SEED)
    kind_class(kind).fit_measurement(m).save(tmp / "k.kes.json")
    model = load(tmp / "k.kes.json")
    out = {"default": kesbrdf.fit(m)[0].kind if default else None}
    for tag, wi, wr_, truth in truth_sets(ref, protocol):
        out[tag] = {"r": log_error(model.evaluate(wi, wr_), truth), "parts": sigma_inputs(model, wi, wr_)}
    return out


def cases(ref, tmp: Path, protocol: str = "paper") -> dict:
    """{case: ingredients of σ} of one reference, σ from the saved-and-loaded model file
    (``fibre-prior`` on the paper protocol, ``fibre-coord`` on the dense one: each
    protocol's default kind)."""
    m = measure(ref, protocol=protocol, noise=NOISE, noise_floor=1e-4, rng=SEED)
    kind = FibrePriorModel if protocol == "paper" else kind_class("fibre-coord")
    kind.fit_measurement(m).save(tmp / "m.kes.json")
    model = load(tmp / "m.kes.json")
    s = misfit_level(model)
    out = {}
    for tag, wi, wr_, truth in truth_sets(ref):
        f = model.evaluate(wi, wr_)
        parts = variance_parts(model, wi, wr_, f)
        d_slice, d_psi = support_distance_parts(model.support, wi, wr_)
        r = log_error(f, truth)
        out[tag] = {"r": r, "base": parts["fit"] + parts["spread"], "law": parts["theta_d_law"], "s": s,
                    "d": support_distance(model.support, wi, wr_)[:, None], "d_slice": d_slice[:, None],
                    "d_psi": d_psi[:, None]}
    return out


def sigma_log(c: dict, form: str, p) -> np.ndarray:
    """σ of ln f of one case: ``before`` (p = c), ``after`` (p = (c_ψ, q, c₀, c₁)) or
    ``kes`` (p = (a, q, b₀, b₁) of eq. K1)."""
    if form == "kes":
        return combine(c["parts"], dict(zip(KES_KEYS, p)))
    if form == "before":
        var = c["base"] + c["law"] + (p * c["d"]) ** 2
    else:
        var = c["base"] + (p[0] * c["s"] ** p[1] * c["d_psi"]) ** 2 + ((p[2] + p[3] * c["s"]) * c["d_slice"]) ** 2
    return np.minimum(np.sqrt(var), CAP)


def family_coverage(rows, form, p) -> dict:
    """{case: [mean cov₁, mean cov₂]} over a family's references."""
    out = {}
    for tag in CASES:
        cov = []
        for ref_cases in rows:
            c = ref_cases[tag]
            z = c["r"] / np.maximum(sigma_log(c, form, p), 1e-12)
            cov.append((np.mean(z <= 1), np.mean(z <= 2)))
        out[tag] = [round(float(np.mean([x[0] for x in cov])), 4), round(float(np.mean([x[1] for x in cov])), 4)]
    return out


def _hinge(x, lo, hi):
    return max(lo - x, 0.0) + max(x - hi, 0.0)


def family_loss(cov: dict) -> float:
    """Mean over cases of the squared distance outside the bands + a small Gaussian pull."""
    return float(np.mean([_hinge(c1, *BAND1) ** 2 + _hinge(c2, *BAND2) ** 2
                          + 0.05 * ((c1 - TARGET[0]) ** 2 + (c2 - TARGET[1]) ** 2) for c1, c2 in cov.values()]))


def in_bands(cov: dict) -> bool:
    return all(BAND1[0] <= c1 <= BAND1[1] and BAND2[0] <= c2 <= BAND2[1] for c1, c2 in cov.values())


def loss_table(fams: dict, form: str, grid) -> np.ndarray:
    """(len(grid), n_families) family losses, computed once for every fold; +inf where a
    reference of the family falls below ``REF_FLOOR_2SIGMA`` at held-out orientations."""
    def one(rows, p):
        floor = min(family_coverage([rc], form, p)["held_out"][1] for rc in rows)
        return family_loss(family_coverage(rows, form, p)) if floor >= REF_FLOOR_2SIGMA else np.inf
    return np.array([[one(rows, p) for rows in fams.values()] for p in grid])


def lofo_params(fam_names, table, grid) -> dict:
    """{family: the grid point minimising the mean loss over the other families}."""
    out = {}
    for j, fam in enumerate(fam_names):
        keep = [k for k in range(len(fam_names)) if k != j]
        out[fam] = grid[int(np.argmin(table[:, keep].mean(axis=1)))]
    return out


def mean_coverage(covs) -> dict:
    """{case: [mean cov₁, mean cov₂]} of per-reference coverages (None when empty)."""
    if not covs:
        return None
    return {tag: [round(float(np.mean([c[tag][k] for c in covs])), 4) for k in (0, 1)] for tag in CASES}


def default_lofo(fams, kes_fams, names, prior_params, kes_params) -> dict:
    """Coverage of the default model's σ per family left out, before (fibre-prior only)
    and after (kes with eq. K1), each kind with its scales fitted without the family."""
    out = {}
    for fam, rows in fams.items():
        kinds = [kc["default"] for kc in kes_fams[fam]]
        prior_cov = [family_coverage([rc], "after", prior_params[fam]) for rc, k in zip(rows, kinds) if k != "kes"]
        kes_cov = [family_coverage([kc], "kes", kes_params[fam]) for kc, k in zip(kes_fams[fam], kinds) if k == "kes"]
        after = mean_coverage(prior_cov + kes_cov)
        out[fam] = {"default_kinds": dict(zip(names[fam], kinds)), "without_sigma_before": kinds.count("kes"),
                    "before": mean_coverage(prior_cov), "after": after,
                    "in_bands_before": bool(kinds.count("kes") == 0 and in_bands(mean_coverage(prior_cov))),
                    "in_bands_after": in_bands(after)}
    return out


def table_section(tab_fams, names, frozen_scales: dict, grid=GRID_KES):
    """(result, LOFO parameters) of eq. K1 on the table fits ``tab_fams`` ({family:
    [table_cases]}): the coverage of each family left out, the scales on all families,
    and the coverage at ``frozen_scales`` per family and per reference."""
    fam_names = list(tab_fams)
    table = loss_table(tab_fams, "kes", grid)
    params = lofo_params(fam_names, table, grid)
    frozen = tuple(frozen_scales[k] for k in KES_KEYS)
    result = {"lofo": {fam: {"params": [float(v) for v in params[fam]],
                             "coverage": family_coverage(tab_fams[fam], "kes", params[fam]),
                             "in_bands": in_bands(family_coverage(tab_fams[fam], "kes", params[fam]))}
                       for fam in fam_names},
              "params_all_families": [float(v) for v in grid[int(np.argmin(table.mean(axis=1)))]],
              "frozen": dict(frozen_scales),
              "coverage_frozen": {fam: family_coverage(rows, "kes", frozen) for fam, rows in tab_fams.items()},
              "coverage_frozen_references": {f"{fam}/{n}": family_coverage([kc], "kes", frozen)
                                             for fam, rows in tab_fams.items() for n, kc in zip(names[fam], rows)}}
    result["families_in_bands_lofo"] = sum(r["in_bands"] for r in result["lofo"].values())
    return result, params


def run_kes(fams, kes_fams, names, prior_params) -> dict:
    """The kes section (module docstring): LOFO coverage of eq. K1 on every reference's
    kes fit, the scales on all families, and the default model's coverage."""
    result, params = table_section(kes_fams, names, KES_SIGMA_SCALES)
    result["default_lofo"] = default_lofo(fams, kes_fams, names, prior_params, params)
    return result


def run_halfdiff(default: bool = True) -> dict:
    """The kes_halfdiff section (module docstring): eq. K1 with the kes-halfdiff
    coordinates on every reference's kes-halfdiff fit of the dense measurement (6°),
    scored on the held-out orientations (dense geometry) and both hemispheres, LOFO;
    ``default_lofo``: the same coverage over the references whose default model on the
    dense measurement is kes-halfdiff (the others keep fibre-coord's σ,
    ``dense_fibre_coord_frozen``)."""
    hd_fams, names = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for fam, refs in references().items():
            if refs:
                hd_fams[fam] = [table_cases(ref, Path(tmp), "kes-halfdiff", "dense", default) for ref in refs.values()]
                names[fam] = list(refs)
                print(f"{fam}: {len(refs)} references (kes-halfdiff)", file=sys.stderr)
    result, params = table_section(hd_fams, names, HALFDIFF_SIGMA_SCALES, GRID_HALFDIFF)
    result["protocol"] = "dense"
    result["default_lofo"] = {}
    for fam, rows in hd_fams.items():
        kinds = [rc["default"] for rc in rows]
        kept = [rc for rc, k in zip(rows, kinds) if k == "kes-halfdiff"]
        result["default_lofo"][fam] = {
            "default_kinds": dict(zip(names[fam], kinds)),
            "after": mean_coverage([family_coverage([rc], "kes", params[fam]) for rc in kept])}
    return result


def run(dense: bool = True) -> dict:
    fams, names, kes_fams = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for fam, refs in references().items():
            if refs:
                fams[fam] = [cases(ref, Path(tmp)) for ref in refs.values()]
                kes_fams[fam] = [table_cases(ref, Path(tmp)) for ref in refs.values()]
                names[fam] = list(refs)
                print(f"{fam}: {len(refs)} references", file=sys.stderr)
    result = {"noise": NOISE, "seed": SEED, "hemi_step_deg": HEMI_STEP_DEG, "bands": [list(BAND1), list(BAND2)],
              "misfit_s": {f"{fam}/{n}": round(float(rows[i]["held_out"]["s"]), 4)
                           for fam, rows in fams.items() for i, n in enumerate(names[fam])},
              "lofo": {}}
    fam_names = list(fams)
    tables = {"before": (GRID_BEFORE, loss_table(fams, "before", GRID_BEFORE)),
              "after": (GRID_AFTER, loss_table(fams, "after", GRID_AFTER))}
    summary = {"before": 0, "after": 0}
    for j, fam in enumerate(fam_names):
        row = {}
        for form, (grid, table) in tables.items():
            keep = [k for k in range(len(fam_names)) if k != j]
            p = grid[int(np.argmin(table[:, keep].mean(axis=1)))]
            cov = family_coverage(fams[fam], form, p)
            row[form] = {"params": [float(v) for v in np.atleast_1d(p)], "coverage": cov, "in_bands": in_bands(cov)}
            summary[form] += in_bands(cov)
        result["lofo"][fam] = row
    result["families_in_bands_lofo"] = summary
    for form, (grid, table) in tables.items():
        result[f"params_all_families_{form}"] = [float(v) for v in np.atleast_1d(grid[int(np.argmin(table.mean(axis=1)))])]
    frozen = tuple(SIGMA_SCALES[k] for k in ("azimuth", "azimuth_power", "slice", "slice_misfit"))
    result["frozen"] = {"SIGMA_SCALES": dict(SIGMA_SCALES), "OFF_SUPPORT_SCALE": OFF_SUPPORT_SCALE}
    result["coverage_frozen"] = {fam: {"before": family_coverage(rows, "before", OFF_SUPPORT_SCALE),
                                       "after": family_coverage(rows, "after", frozen)} for fam, rows in fams.items()}
    result["coverage_frozen_references"] = {
        f"{fam}/{name}": family_coverage([ref_cases], "after", frozen)
        for fam, rows in fams.items() for name, ref_cases in zip(names[fam], rows)}
    result["kes"] = run_kes(fams, kes_fams, names, lofo_params(fam_names, tables["after"][1], GRID_AFTER))
    result["kes_halfdiff"] = run_halfdiff()
    if not dense:
        return result
    # the dense protocol's default (fibre-coord) with the same scales: reported, not fitted
    dense = {}
    with tempfile.TemporaryDirectory() as tmp:
        for fam, refs in references().items():
            if refs:
                dense[fam] = [cases(ref, Path(tmp), "dense") for ref in refs.values()]
    result["dense_fibre_coord_frozen"] = {fam: {"before": family_coverage(rows, "before", OFF_SUPPORT_SCALE),
                                                "after": family_coverage(rows, "after", frozen)}
                                          for fam, rows in dense.items()}
    return result


if __name__ == "__main__":  # pragma: no cover
    # ``halfdiff``: the kes_halfdiff section alone
    print(json.dumps(run_halfdiff() if sys.argv[1:] == ["halfdiff"] else run(), indent=1))
