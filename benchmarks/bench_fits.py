"""Analytic-fit benchmark: how well glTF PBR, OpenPBR, Standard Surface and UsdPreviewSurface
approximate KES fabrics, and what the analytic exports of the demo model cost.

For each fabric reference (anisotropic Ward, Sadeghi 2013 presets, the demo's black satin,
Irawan's cotton twill, the RGL white felt), simulate the paper's protocol
(``kesbrdf.measure.gonio.measure``), fit the KES model (``kesbrdf.models.kes.fit(..., fallback="log")``),
then fit each analytic material to that model with
:func:`kesbrdf.export.analytic_fit.fit_analytic_uncached` (default grid) and record the
image-space error (the objective, on the error grid), the BRDF-space errors (NRMSE,
relative L1), the parameters that ended at a bound of their physical range, the fitted
anisotropy rotation and the fit's CPU time.

``demo_exports``: CPU seconds of the glTF, GLB, MaterialX and USD exports of the demo's
KES model in one process with an empty fit cache, then again in the same process, then
with only the on-disk cache (as a new ``kesbrdf export`` process would).
Run alone with ``PYTHONPATH=src python benchmarks/run.py --only fits --output /tmp/fits.json``.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from pathlib import Path

REFERENCES = ("ward", "satin", "linen", "velvet", "silk_shot", "black_satin", "cotton_twill", "white_felt")


def _reference(name):
    from kesbrdf.references.sadeghi2013 import Sadeghi2013, black_satin
    from kesbrdf.references.ward import AnisotropicWard

    if name == "ward":
        return AnisotropicWard(0.1, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.08)
    if name == "black_satin":
        return black_satin()
    if name == "cotton_twill":
        from kesbrdf.references.irawan2012 import Irawan2012

        return Irawan2012("cotton_twill")
    if name == "white_felt":
        from kesbrdf.references.rgl_tensor import RGLTensorBRDF

        return RGLTensorBRDF(Path(__file__).resolve().parents[1] / "src" / "kesbrdf" / "data" / "rgl" / "acrylic_felt_white_rgb.bsdf")
    return Sadeghi2013(name)


def _demo_exports() -> dict:
    """CPU of the four analytic exports of the demo model: empty cache, memory, disk."""
    from kesbrdf.measure import demo_data
    from kesbrdf.export import export, fit_cache
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.models.kes import fit

    model = fit(read_measurement(demo_data.embedded_measurement()))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get(fit_cache.CACHE_ENV)
        os.environ[fit_cache.CACHE_ENV] = str(Path(tmp) / "cache")
        try:
            for label in ("empty_cache", "memory_cache", "disk_cache"):
                if label == "disk_cache":
                    fit_cache.clear_memory()
                c0 = time.process_time()
                per = {}
                for fmt, name in (("gltf", "f.gltf"), ("glb", "f.glb"), ("mtlx", "f.mtlx"), ("usd", "f.usda")):
                    c = time.process_time()
                    export(model, fmt, Path(tmp) / label / name)
                    per[fmt] = time.process_time() - c
                out[label] = {"cpu_s": time.process_time() - c0, "per_format_cpu_s": per}
                print(f"bench fits: demo exports ({label}) {out[label]['cpu_s']:.1f}s CPU", file=sys.stderr, flush=True)
        finally:
            if old is None:
                os.environ.pop(fit_cache.CACHE_ENV, None)
            else:
                os.environ[fit_cache.CACHE_ENV] = old
    return out


def run() -> dict:
    from kesbrdf.export.analytic_fit import fit_analytic_uncached
    from kesbrdf.export.gltf_pbr import GLTF_PBR
    from kesbrdf.export.openpbr import OPENPBR
    from kesbrdf.export.preview_surface import PREVIEW_SURFACE
    from kesbrdf.export.standard_surface import STANDARD_SURFACE
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    results: dict = {}
    for name in REFERENCES:
        model = fit(measure(_reference(name)), fallback="log")
        per = {}
        for material in (GLTF_PBR, OPENPBR, STANDARD_SURFACE, PREVIEW_SURFACE):
            c0 = time.process_time()
            res = fit_analytic_uncached(material, model)
            cpu = time.process_time() - c0
            e = res.error
            print(f"bench fits: {name} {material.name} image RMSE {e['image_rmse']:.4f}, NRMSE {e['nrmse']:.3f} "
                  f"in {cpu:.1f}s CPU; at bounds {e['at_bounds']}", file=sys.stderr, flush=True)
            row = {
                "image_rmse": e["image_rmse"],
                "nrmse": e["nrmse"],
                "nrmse_theta_le_70": e["nrmse_theta_le_70"],
                "rel_l1": e["rel_l1"],
                "log_rmse": e["log_rmse"],
                "at_bounds": e["at_bounds"],
                "params": res.params,
                "basin_costs": [b["cost"] for b in res.basins],
                "worst_config_deg": [e["worst"][0][k] for k in ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")],
                "fit_cpu_seconds": cpu,
            }
            if material.rotation:
                rot = res.params[material.rotation]
                row["rotation_deg"] = math.degrees(rot) if material.name != "standard_surface" else 360.0 * rot
            per[material.name] = row
        results[name] = per
    results["demo_exports"] = _demo_exports()
    return results


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
