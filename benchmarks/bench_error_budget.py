"""Where the paper protocol's hemisphere error lives, per family (issue 20).

For the first ``PER_FAMILY`` fabrics of each family of the synthetic fabric library
(:func:`kesbrdf.validate.library.draw_fabric`, seed 0: the library's own fabrics and
noise draws, computed here so that the library need not be built), ``kesbrdf.fit``'s
default model of the paper protocol's 116 samples is scored on both Fig. 6
hemispheres, and the squared error is split by the deviation γ from the mirror
direction (:func:`kesbrdf.validate.compare.deviation_bands`).  Per family, the medians
over its fabrics of

* each band's share of the squared error and its median model/truth ratio;
* the directional albedo of the model over the reference's, at θ_i = 0° and 45°
  (φ_i = 90°; :func:`kesbrdf.geometry.grazing_albedo`), the overall brightness a render
  shows at one exposure;

and the hemisphere NRMSE itself.  A few minutes on one core.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

import numpy as np  # noqa: E402

#: Fabrics per family (library indices k with k mod 5 = the family's place).
PER_FAMILY = 3
#: Incidence polar angles (degrees) of the albedo ratio, at φ_i = 90°.
ALBEDO_THETA_DEG = (0.0, 45.0)


def fabric_budget(spec: dict, geom: dict) -> dict:
    """One fabric: hemisphere NRMSE, bands and albedo ratios of its default paper fit."""
    import kesbrdf
    from kesbrdf.geometry import grazing_albedo
    from kesbrdf.measure.gonio import measure
    from kesbrdf.validate.compare import deviation_bands, metrics
    from kesbrdf.validate.library import NOISE, build_reference, noise_seed

    ref = build_reference(spec)
    m = measure(ref, protocol="paper", noise=NOISE, rng=noise_seed(0, spec["index"], "paper"))
    t0 = time.process_time()
    model = kesbrdf.fit(m)[0]
    cpu = time.process_time() - t0
    wi = np.concatenate([geom["hemi90_wi"], geom["hemi45_wi"]])
    wr = np.concatenate([geom["hemi90_wr"], geom["hemi45_wr"]])
    truth = np.asarray(ref(wi, wr), float)
    pred = np.asarray(model.evaluate(wi, wr), float)
    nrmse = float(np.mean([metrics(pred[s], truth[s])["all"]["nrmse"]
                           for s in (slice(0, len(wi) // 2), slice(len(wi) // 2, None))]))
    albedo = {}
    for th in ALBEDO_THETA_DEG:
        a_ref = float(np.mean(grazing_albedo(ref, th, 90.0, n_s=32, n_phi=64)))
        a_mod = float(np.mean(grazing_albedo(model.evaluate, th, 90.0, n_s=32, n_phi=64)))
        albedo[f"{th:g}"] = a_mod / a_ref
    return {"kind": model.kind, "fit_cpu_s": cpu, "hemispheres": nrmse,
            "bands": deviation_bands(pred, truth, wi, wr), "albedo_ratio": albedo}


def family_medians(rows: list[dict]) -> dict:
    """Medians over a family's fabrics of every band's share and ratio, the albedo ratios
    and the hemisphere NRMSE."""
    out = {"hemispheres": float(np.median([r["hemispheres"] for r in rows])),
           "kinds": sorted({r["kind"] for r in rows}),
           "albedo_ratio": {k: float(np.median([r["albedo_ratio"][k] for r in rows])) for k in rows[0]["albedo_ratio"]},
           "bands": {}}
    for b in rows[0]["bands"]:
        key = f"{b['lo']:g}-{b['hi']:g}"
        same = [x for r in rows for x in r["bands"] if x["lo"] == b["lo"]]
        out["bands"][key] = {"share": float(np.median([x["share"] for x in same])),
                             "ratio": float(np.median([x["ratio"] for x in same]))}
    return out


def run(per_family: int = PER_FAMILY) -> dict:
    from kesbrdf.validate.library import LIBRARY_FAMILIES, draw_fabric, geometry

    geom = geometry()
    fabrics, families = {}, {}
    n_fam = len(LIBRARY_FAMILIES)
    for j, fam in enumerate(LIBRARY_FAMILIES):
        rows = []
        for i in range(per_family):
            spec = draw_fabric(0, j + n_fam * i)
            assert spec["family"] == fam
            row = fabric_budget(spec, geom)
            fabrics[spec["name"]] = row
            rows.append(row)
            print(f"error_budget {spec['name']}: {row['kind']} hemispheres {row['hemispheres']:.3f}, shares "
                  + " ".join(f"{b['lo']:g}-{b['hi']:g}:{b['share']:.2f}x{b['ratio']:.2f}" for b in row["bands"])
                  + f", albedo ratio {row['albedo_ratio']}", file=sys.stderr, flush=True)
        families[fam] = family_medians(rows)
    return {"protocol": "paper", "per_family": per_family, "library_seed": 0, "families": families, "fabrics": fabrics}


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run()["families"], indent=1))
