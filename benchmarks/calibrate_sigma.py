"""Leave-one-family-out choice of the off-support σ scale (prior_model.OFF_SUPPORT_SCALE).

For every reference of every family of benchmarks/bench_prior.py (Irawan–Marschner and
Sadeghi presets, Ward, Ashikhmin–Shirley, the RGL felt when Mitsuba imports), the
paper protocol is measured with 2 % noise (seeded), the ``fibre-prior`` kind is fitted
and saved/loaded through a model file (the σ users get), and three cases are scored:
the held-out orientations ψ = 15 … 165° (noise-free truth), and the Fig. 6 hemispheres
θ_i = 30°, φ_i = 90° and 45° (5° viewer grid).

σ² = v₀ + (c·d)² (eq. U1): v₀ is every term but the off-support one, d the distance from
the measured support.  A constant c is scored per family by the mean over its
references and cases of (cov₁ − 0.683)² + (cov₂ − 0.954)², cov_k the fraction of truths
within kσ.  Leave-one-family-out: for each family, c is fitted on the other families
and the coverage on the left-out family is reported; then c is fitted on all.

Run:  python benchmarks/calibrate_sigma.py  (prints JSON; a few minutes on one core).
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
from kesbrdf.models.fibre_prior import OFF_SUPPORT_SCALE, FibrePriorModel, _variance_terms, support_distance  # noqa: E402
from kesbrdf.validate.compare import HELD_OUT_DEG, HEMISPHERE_LIGHTS_DEG, hemisphere_directions  # noqa: E402

NOISE = 0.02
SEED = 3
HEMI_STEP_DEG = 5.0
#: Candidate scales (σ of ln f per radian), log-spaced plus 0.
GRID = np.concatenate([[0.0], np.geomspace(0.01, 10.0, 121)])
TARGET = (0.683, 0.954)


def cases(ref, tmp: Path):
    """[(case, |Δ ln f|, v₀, d)] of one reference, σ from the saved-and-loaded model file."""
    m = measure(ref, noise=NOISE, noise_floor=1e-4, rng=SEED)
    FibrePriorModel.fit_measurement(m).save(tmp / "m.kes.json")
    model = load(tmp / "m.kes.json")
    held = measure(ref, orientations_deg=HELD_OUT_DEG)
    wr, _, _ = hemisphere_directions(HEMI_STEP_DEG)
    wr = wr.reshape(-1, 3)
    sets = [("held_out", held.wi, held.wr, held.values)]
    for (ti, pi), tag in zip(HEMISPHERE_LIGHTS_DEG, ("hemi90", "hemi45")):
        wi = np.broadcast_to(spherical_to_cartesian(np.radians(ti), np.radians(pi)), wr.shape)
        sets.append((tag, wi, wr, np.asarray(ref(wi, wr), float)))
    out = []
    for tag, wi, wr_, truth in sets:
        wi, wr_ = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wr_, float))
        f = model.evaluate(wi, wr_)
        v0 = _variance_terms(model, wi, wr_, f)
        kes, model.kes = model.kes, None
        v_old = _variance_terms(model, wi, wr_, f)  # the σ of files without the KES candidate
        model.kes = kes
        d = support_distance(model.support, wi, wr_)
        eps = max(float(np.max(truth)), 1e-300) * 1e-4
        r = np.abs(np.log(np.maximum(truth, 0) + eps) - np.log(np.maximum(f, 0) + eps))
        out.append((tag, r, v0, np.broadcast_to(d[:, None], r.shape), v_old))
    return out


def coverage_at(c, r, v0, d, cap=3.0):
    sl = np.minimum(np.sqrt(v0 + (c * d) ** 2), cap)
    z = r / np.maximum(sl, 1e-12)
    return float(np.mean(z <= 1)), float(np.mean(z <= 2))


def family_loss(c, rows):
    """Mean over a family's references and cases of the squared coverage misses."""
    losses = []
    for ref_cases in rows:
        for _, r, v0, d, _ in ref_cases:
            c1, c2 = coverage_at(c, r, v0, d)
            losses.append((c1 - TARGET[0]) ** 2 + (c2 - TARGET[1]) ** 2)
    return float(np.mean(losses))


def best_scale(fams: dict) -> float:
    """The grid value minimising the mean family loss (each family weighs the same)."""
    loss = [np.mean([family_loss(c, rows) for rows in fams.values()]) for c in GRID]
    return float(GRID[int(np.argmin(loss))])


def family_coverage(c, rows, old=False) -> dict:
    """{case: [mean cov₁, mean cov₂]} over a family's references (``old``: the σ of files
    without the KES candidate and the off-support term)."""
    out = {}
    for tag in ("held_out", "hemi90", "hemi45"):
        cov = [coverage_at(0.0, r, vo, d) if old else coverage_at(c, r, v0, d)
               for ref_cases in rows for t, r, v0, d, vo in ref_cases if t == tag]
        out[tag] = [float(np.mean([x[0] for x in cov])), float(np.mean([x[1] for x in cov]))]
    return out


def run() -> dict:
    fams, names = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for fam, refs in references().items():
            if refs:
                fams[fam] = [cases(ref, Path(tmp)) for ref in refs.values()]
                names[fam] = list(refs)
                print(f"{fam}: {len(refs)} references", file=sys.stderr)
    result = {"noise": NOISE, "seed": SEED, "hemi_step_deg": HEMI_STEP_DEG, "lofo": {}}
    for fam in fams:
        c = best_scale({k: v for k, v in fams.items() if k != fam})
        result["lofo"][fam] = {"scale": c, "coverage": family_coverage(c, fams[fam]),
                               "coverage_without_term": family_coverage(0.0, fams[fam]),
                               "coverage_old_file": family_coverage(0.0, fams[fam], old=True)}
    c_all = best_scale(fams)
    result["scale_all_families"] = c_all
    result["coverage_all"] = {fam: family_coverage(c_all, rows) for fam, rows in fams.items()}
    # the constant frozen in the code (c_all rounded), per family and per reference
    result["frozen_scale"] = OFF_SUPPORT_SCALE
    result["coverage_frozen"] = {fam: family_coverage(OFF_SUPPORT_SCALE, rows) for fam, rows in fams.items()}
    result["coverage_frozen_references"] = {
        f"{fam}/{name}": family_coverage(OFF_SUPPORT_SCALE, [ref_cases])
        for fam, rows in fams.items() for name, ref_cases in zip(names[fam], rows)}
    return result


if __name__ == "__main__":  # pragma: no cover
    print(json.dumps(run(), indent=1))
