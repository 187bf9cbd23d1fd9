"""Analytic-fit benchmark: how well glTF PBR, OpenPBR and Standard Surface approximate KES fabrics.

For each fabric reference (anisotropic Ward and Sadeghi 2013 presets), simulate the
paper's protocol (``kesbrdf.gonio.measure``), fit the KES model
(``kesbrdf.model.fit(..., fallback="log")``), then fit each analytic material to that
model with :func:`kesbrdf.export.analytic_fit.fit_analytic` (:data:`BENCH_FIT_GRID`) and record
the fit error (NRMSE, relative L1, log-RMSE on the error grid), the worst
configuration, the fitted anisotropy rotation and the fit time.
Run alone with ``PYTHONPATH=src python benchmarks/run.py --only fits --output /tmp/fits.json``.
"""

from __future__ import annotations

import math
import sys
import time

REFERENCES = ("ward", "satin", "linen", "velvet", "silk_shot")
#: fit grid of the benchmark: 6 × 12 incident × 8 × 16 outgoing directions (9216 pairs),
#: a quarter of the export default so the 15 fits stay within minutes on a shared
#: machine; the error grid is the export default (147 456 pairs)
BENCH_FIT_GRID = ((6, 12), (8, 16))


def _reference(name):
    from kesbrdf.references.sadeghi2013 import Sadeghi2013
    from kesbrdf.references.ward import AnisotropicWard

    if name == "ward":
        return AnisotropicWard(0.1, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.08)
    return Sadeghi2013(name)


def run() -> dict:
    from kesbrdf.export.analytic_fit import fit_analytic
    from kesbrdf.export.gltf_pbr import GLTF_PBR
    from kesbrdf.export.openpbr import OPENPBR
    from kesbrdf.export.standard_surface import STANDARD_SURFACE
    from kesbrdf.gonio import measure
    from kesbrdf.model import fit

    results: dict = {}
    for name in REFERENCES:
        model = fit(measure(_reference(name)), fallback="log")
        per = {}
        for material in (GLTF_PBR, OPENPBR, STANDARD_SURFACE):
            t0 = time.perf_counter()
            res = fit_analytic(material, model, grid=BENCH_FIT_GRID)
            print(f"bench fits: {name} {material.name} NRMSE {res.error['nrmse']:.3f} (theta <= 70: {res.error['nrmse_theta_le_70']:.3f}) in {time.perf_counter() - t0:.1f}s", file=sys.stderr, flush=True)
            seconds = time.perf_counter() - t0
            rot = res.params[material.rotation]
            rot_deg = math.degrees(rot) if material.name != "standard_surface" else 360.0 * rot
            worst = res.error["worst"][0]
            per[material.name] = {
                "nrmse": res.error["nrmse"],
                "nrmse_theta_le_70": res.error["nrmse_theta_le_70"],
                "rel_l1": res.error["rel_l1"],
                "log_rmse": res.error["log_rmse"],
                "rotation_deg": rot_deg,
                "basin_costs": [b["cost"] for b in res.basins],
                "worst_config_deg": [worst["theta_i_deg"], worst["phi_i_deg"], worst["theta_r_deg"], worst["phi_r_deg"]],
                "fit_seconds": seconds,
            }
        results[name] = per
    return results


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
