"""Grazing energy: directional albedo of every model kind x reference family, model vs
reference, at θ_i = 0, 60, 80, 89, 89.9, 89.99° (docs/decisions.md, "Grazing energy").

Each reference is measured noise-free in the paper's protocol (``kes``, ``scattered``,
``fibre-prior``) or the dense 6° protocol (``kes-halfdiff``), fitted with
``kesbrdf.fit(kind=...)``, and the directional albedo of model and reference is
integrated by :func:`kesbrdf.validate.diagnostics.grazing_albedo` at light azimuths φ_i = 0° and
90° (warp and weft); the table holds the larger of the two, channel mean.  The
quadrature error is estimated per row as the largest change when both resolutions are
doubled (``quad_err``).  ``gain`` = largest albedo at θ_i ≥ 80° over the largest at
θ_i ≤ 60° (how much the model brightens toward grazing incidence), for the model and
for the reference.  ``bound`` is the model's own energy bound at any incidence,
π·c + ∫max_φ q(φ, γ) dω / λ over the deviations γ the lobe covers (``kes`` tables only).

The "before" table of ``results.json`` was made by this module on the source tree
before the fix (commit 27c3494, with this ``kesbrdf.validate.diagnostics``); ``code`` says which.

``fibre_prior_energy_scale`` (``python benchmarks/bench_energy.py --fibre-prior``, merged
into ``results.json`` → ``energy`` by itself) is the ``fibre-prior`` column with and
without the energy scale g of :mod:`kesbrdf.models.fibre_prior` (without = the fit as it was
before it), and the held-out / hemisphere NRMSE of prior + residual
(``benchmarks/bench_prior.py``'s :func:`evaluate_reference`) on a few families, both ways.
"""

from __future__ import annotations

import math
import time

import numpy as np

KINDS = ("kes", "kes-halfdiff", "scattered", "fibre-prior")
FAMILIES = (
    "ward", "satin-ward", "ashikhmin-shirley", "sadeghi-satin", "sadeghi-black-satin", "sadeghi-linen",
    "sadeghi-silk-crepe", "sadeghi-silk-shot", "sadeghi-velvet", "irawan-silk-charmeuse", "rgl-felt-white",
)
PHI_I_DEG = (0.0, 90.0)
N_S, N_PHI = 96, 192


def _reference(name):
    if name.startswith("irawan-"):
        from kesbrdf.references.irawan2012 import Irawan2012

        return Irawan2012(name[len("irawan-"):].replace("-", "_"))
    from kesbrdf.references.registry import make_reference

    return make_reference(name)


def _fit(ref, kind):
    import kesbrdf
    from kesbrdf.measure.gonio import measure

    m = measure(ref, protocol="dense" if kind == "kes-halfdiff" else "paper")
    model, _ = kesbrdf.fit(m, kind=kind)
    return model


def _albedo(brdf, n_s=N_S, n_phi=N_PHI):
    from kesbrdf.validate.diagnostics import GRAZING_ANGLES_DEG, grazing_albedo

    per_phi = [grazing_albedo(brdf, GRAZING_ANGLES_DEG, p, n_s, n_phi).mean(axis=1) for p in PHI_I_DEG]
    return np.max(per_phi, axis=0)


def _bound(model) -> float | None:
    """π·c + (1/λ)·2π ∫ max_φ q(φ, γ) sin γ dγ of a ``kes`` table (channel mean), γ ≤ γ_max
    (+ the fade), or up to π when held."""
    if model.kind != "kes":
        return None
    from kesbrdf.models import mappings

    if getattr(model, "normalisation", "sqrtcos") != "bounded":
        return math.inf  # 1/√(cos θ_i cos θ_r): unbounded as θ_i → 90°
    lam, fade_deg = mappings.BOUNDED_LAMBDA, mappings.FADE_DEG
    g = np.linspace(0.0, math.pi, 2001)
    q = model.table.mean(axis=-1).max(axis=0)  # (n_gamma,)
    qg = np.interp(g, model.gamma_grid, q)
    if model.extrapolation == "fade":
        qg = qg * np.clip(1.0 - (g - model.gamma_max) / math.radians(fade_deg), 0.0, 1.0)
    lobe = 2 * math.pi * np.trapezoid(qg * np.sin(g), g) / lam
    return float(math.pi * np.mean(model.body) + lobe)


def _hemisphere_rmse() -> dict:
    """Fig. 6 hemispheres and held-out orientations (:func:`kesbrdf.validate.compare.compare_reference`)
    of the ``kes`` fit, before (``sqrtcos`` + ``hold``) and after the fix, RMSE in 1/sr:
    what the fix costs or gains away from grazing."""
    from kesbrdf.measure.gonio import measure
    from kesbrdf.validate.compare import compare_reference

    out = {}
    for fam in FAMILIES:
        try:
            ref = _reference(fam)
        except Exception:
            continue
        m = measure(ref)
        row = {}
        for label, kw in (("before", {"normalisation": "sqrtcos", "extrapolation": "hold"}), ("after", {})):
            cases = compare_reference(m, ref, interpolations=("kes",), **kw)["cases"]
            row[label] = {c.replace("hemisphere_", ""): round(v["kes"]["all"]["rmse"], 4) for c, v in cases.items()}
        out[fam] = row
    return out


def plugin_sample_weights(families=("ward", "sadeghi-silk-crepe"), theta_r_deg=(60.0, 89.0, 89.9, 89.99),
                          n: int = 1 << 16, seed: int = 1) -> dict:
    """Sample weights f·cos θ/pdf of the ``kesbrdf`` Mitsuba plugin (its own lobe sampling)
    for a viewer at θ_r, on a ``kes`` fit of each family (paper protocol): the mean is the
    white-furnace value a pixel converges to, the tail (max, share above 5× the mean) is
    what shows as fireflies at 64 spp.  None without Mitsuba."""
    try:
        import drjit as dr
        import mitsuba as mi

        import kesbrdf.render  # noqa: F401  (variant, plugins)
    except Exception:
        return None
    import tempfile
    from pathlib import Path

    import kesbrdf
    from kesbrdf.measure.gonio import measure

    out = {}
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        for fam in families:
            model, _ = kesbrdf.fit(measure(_reference(fam)), kind="kes")
            path = Path(tmp) / f"{fam}.kes.json"
            model.save(path)
            bsdf = mi.load_dict({"type": "kesbrdf", "filename": str(path)})
            rows = {}
            for th in theta_r_deg:
                t = math.radians(th)
                si = dr.zeros(mi.SurfaceInteraction3f, n)
                si.wi = mi.Vector3f(np.full(n, math.sin(t)), np.zeros(n), np.full(n, math.cos(t)))
                si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
                _, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(rng.random(n)),
                                   mi.Point2f(rng.random(n), rng.random(n)))
                w = np.array(w).mean(axis=0)
                rows[f"{th:g}"] = {"mean": round(float(w.mean()), 4), "max": float(f"{w.max():.3g}"),
                                   "share_above_5x_mean": float(f"{np.mean(w > 5 * w.mean()):.3g}")}
            out[fam] = rows
    return out


def _kind_row(model, a_ref):
    from kesbrdf.validate.diagnostics import GRAZING_ANGLES_DEG

    a = _albedo(model.evaluate)
    a2 = _albedo(model.evaluate, 2 * N_S, 2 * N_PHI)
    lo = np.asarray(GRAZING_ANGLES_DEG) <= 60
    return {
        "model": [round(float(v), 4) for v in a],
        "reference": [round(float(v), 4) for v in a_ref],
        "quad_err": float(f"{np.max(np.abs(a2 - a)):.2g}"),
        "gain_model": round(float(a[~lo].max() / max(a[lo].max(), 1e-12)), 3),
        "gain_reference": round(float(a_ref[~lo].max() / max(a_ref[lo].max(), 1e-12)), 3),
        "bound": _json_bound(_bound(model)),
        "above_one": bool(np.any(a > 1.0)),
    }


#: Families of the fibre-prior accuracy comparison: the two the scale changes most, one
#: it barely touches, one it leaves alone.
ACCURACY_FAMILIES = ("sadeghi-velvet", "sadeghi-silk-crepe", "ashikhmin-shirley", "ward")


def fibre_prior_energy_scale() -> dict:
    """The ``fibre-prior`` rows with and without the energy scale, and the NRMSE cost."""
    import bench_prior

    from kesbrdf.models import fibre_prior as prior_model

    real = prior_model._bound_energy
    t0 = time.perf_counter()
    rows = {"with": {}, "without": {}}
    accuracy = {}
    try:
        for fam in FAMILIES:
            try:
                ref = _reference(fam)
            except Exception as exc:  # an RGL file that is not installed
                rows["with"][fam] = {"error": f"{type(exc).__name__}: {exc}"}
                continue
            a_ref = _albedo(ref)
            for label, bound in (("without", lambda model, m: None), ("with", real)):
                prior_model._bound_energy = bound
                model = _fit(ref, "fibre-prior")
                rows[label][f"{fam} / fibre-prior"] = row = _kind_row(model, a_ref)
                if label == "with":
                    row["energy"] = model.diagnostics.get("energy")
                if fam in ACCURACY_FAMILIES:
                    r = bench_prior.evaluate_reference(ref)
                    accuracy.setdefault(fam, {})[label] = {
                        k.replace("_prior_residual", ""): round(r[k], 4)
                        for k in ("held_out_prior_residual", "hemi90_prior_residual", "hemi45_prior_residual")}
                    accuracy[fam][label]["round_trip_max_rel"] = float(f"{r['round_trip_max_rel']:.2g}")
    finally:
        prior_model._bound_energy = real
    return {
        "what": "fibre-prior directional albedo (as 'rows') without the energy scale g (the fit before it) and "
                "with it; nrmse: prior + residual, benchmarks/bench_prior.py evaluate_reference (paper protocol)",
        "bound": prior_model.ENERGY_BOUND,
        "rows": rows,
        "max_model_albedo": {k: round(max(max(r["model"]) for r in v.values() if "model" in r), 4) for k, v in rows.items()},
        "nrmse_prior_residual": accuracy,
        "seconds": round(time.perf_counter() - t0, 1),
    }


def _json_bound(b):
    return None if b is None else ("unbounded" if math.isinf(b) else round(b, 4))


def run() -> dict:
    from kesbrdf.validate.diagnostics import GRAZING_ANGLES_DEG

    from kesbrdf.models import mappings

    fixed = hasattr(mappings, "foreshortening")
    rows, refs = {}, {}
    t0 = time.perf_counter()
    worst = 0.0
    for fam in FAMILIES:
        try:
            ref = _reference(fam)
        except Exception as exc:  # an RGL file that is not installed
            rows[fam] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        a_ref = _albedo(ref)
        refs[fam] = [round(float(v), 4) for v in a_ref]
        for kind in KINDS:
            model = _fit(ref, kind)
            a = _albedo(model.evaluate)
            a2 = _albedo(model.evaluate, 2 * N_S, 2 * N_PHI)
            worst = max(worst, float(np.max(a)))
            lo = np.asarray(GRAZING_ANGLES_DEG) <= 60
            rows[f"{fam} / {kind}"] = {
                "model": [round(float(v), 4) for v in a],
                "reference": refs[fam],
                "quad_err": float(f"{np.max(np.abs(a2 - a)):.2g}"),
                "gain_model": round(float(a[~lo].max() / max(a[lo].max(), 1e-12)), 3),
                "gain_reference": round(float(a_ref[~lo].max() / max(a_ref[lo].max(), 1e-12)), 3),
                "bound": _json_bound(_bound(model)),
                "above_one": bool(np.any(a > 1.0)),
            }
    return {
        "hemisphere_rmse_kes": _hemisphere_rmse() if fixed else None,
        "plugin_sample_weights": plugin_sample_weights(),
        "what": "directional albedo (max over phi_i = 0, 90 deg; channel mean) of each kind fitted to each "
                "reference family, at theta_i_deg; quadrature kesbrdf.validate.diagnostics.grazing_albedo",
        "code": "bounded foreshortening + fade" if fixed else "before the grazing-energy fix (sqrtcos, hold)",
        "theta_i_deg": list(GRAZING_ANGLES_DEG),
        "quadrature": {"n_s": N_S, "n_phi": N_PHI, "quad_err": "max |a(2 n_s, 2 n_phi) - a(n_s, n_phi)|"},
        "rows": rows,
        "max_model_albedo": round(worst, 4),
        "seconds": round(time.perf_counter() - t0, 1),
        "fibre_prior_energy_scale": fibre_prior_energy_scale(),
    }


def merge_fibre_prior(path=None) -> dict:
    """Rerun only :func:`fibre_prior_energy_scale` and merge it into ``results.json`` →
    ``energy`` (its ``fibre-prior`` rows replaced by the new ones), written atomically."""
    import json
    import os
    from pathlib import Path

    path = Path(path or Path(__file__).resolve().parent / "results.json")
    new = fibre_prior_energy_scale()
    doc = json.loads(path.read_text())
    energy = doc["benchmarks"]["energy"]
    energy["fibre_prior_energy_scale"] = new
    energy["rows"].update(new["rows"]["with"])
    energy["max_model_albedo"] = round(max(max(r["model"]) for r in energy["rows"].values() if "model" in r), 4)
    tmp = path.with_suffix(".part")
    tmp.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    os.replace(tmp, path)
    return new


if __name__ == "__main__":
    import json
    import sys

    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
    if "--fibre-prior" in sys.argv:
        json.dump(merge_fibre_prior(), sys.stdout, indent=1)
    else:
        json.dump(run(), sys.stdout, indent=1)
    print()
