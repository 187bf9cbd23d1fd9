"""Renderer benchmarks (issue 4), measured side by side in one run.

* ``time_ratio_vs_roughconductor``: render time of the ``kesbrdf`` BSDF divided by that
  of Mitsuba's built-in anisotropic ``roughconductor`` (Beckmann, alpha_u ≠ alpha_v) on
  the same draped-cloth scene at equal spp (goal ≤ 1.1, issue 12; was ≤ 1.3, issue 4).  Both are warmed up first so
  the one-off JIT compile is not timed; the median of ``REPEATS`` renders is used.
* ``rmse_ratio_is_vs_cosine``: image RMSE against a high-spp reference at equal spp,
  importance (lobe) sampling divided by cosine sampling (goal ≤ 0.3 for the path tracer,
  issue 12), mean over seeds.

The scene is the procedural folded cloth of ``kesbrdf.render.scenes`` (``drape``
without a folder); set ``KESBRDF_BENCH_DRAPE=<drape folder>`` to use a simulated drape.
The model is fitted from the virtual gonioreflectometer on the satin-like Ward
reference.  About a minute on one core.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

RESOLUTION = (160, 120)
SPP = 32
REF_SPP = 1024
REPEATS = 3
SEEDS = (1, 2, 3)


def _model(path: Path) -> Path:
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.ward import AnisotropicWard

    # the satin-ward reference of the CLI (kesbrdf.cli._common), black satin
    fit(measure(AnisotropicWard(0.08, 0.22, rho_d=0.02, rho_s=0.12))).save(path)
    return path


def _timed(scene, opts, render_scene):
    render_scene(scene, opts)  # warm-up: JIT compile
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        render_scene(scene, opts)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def run() -> dict:
    import kesbrdf.render  # noqa: F401
    from kesbrdf.render.scenes import RenderOptions, load_scene, render_scene

    drape = os.environ.get("KESBRDF_BENCH_DRAPE") or None
    with tempfile.TemporaryDirectory() as tmp:
        model = _model(Path(tmp) / "satin.kes.json")
        base = dict(resolution=RESOLUTION, env="studio", light="area", spp=SPP, max_depth=3)

        # -- time: kesbrdf vs roughconductor ---------------------------------------
        opts = RenderOptions(**base)
        kes_scene = load_scene(model, "drape", opts, drape=drape)
        rc_bsdf = {"type": "twosided", "bsdf": {"type": "roughconductor", "distribution": "beckmann",
                                                 "alpha_u": 0.08, "alpha_v": 0.22}}
        rc_scene = load_scene(model, "drape", opts, drape=drape, cloth_bsdf=rc_bsdf)
        t_kes = _timed(kes_scene, opts, render_scene)
        t_rc = _timed(rc_scene, opts, render_scene)

        # -- noise: importance vs cosine sampling -----------------------------------
        # the cloth alone in the studio environment (no floor, whose diffuse noise is
        # the same for both and would dilute the ratio); two estimators:
        #   path: Mitsuba's path tracer, BSDF sampling combined with emitter sampling (MIS)
        #   bsdf: direct lighting by BSDF sampling alone (what the sampler itself buys)
        integrators = {
            "path": {"type": "path", "max_depth": 3},
            "bsdf": {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1},
        }
        rmse = {}
        for name, integrator in integrators.items():
            common = {**base, "floor": False, "integrator": integrator}
            ref_opts = RenderOptions(**{**common, "spp": REF_SPP}, seed=99)
            ref = render_scene(load_scene(model, "drape", ref_opts, drape=drape), ref_opts)
            for mode in ("lobe", "cosine"):
                errs = []
                for seed in SEEDS:
                    o = RenderOptions(**common, sampling=mode, seed=seed)
                    img = render_scene(load_scene(model, "drape", o, drape=drape), o)
                    errs.append(float(np.sqrt(np.mean((img - ref) ** 2))))
                rmse[name, mode] = float(np.mean(errs))
    return {
        "render_time_kesbrdf_s": t_kes,
        "render_time_roughconductor_s": t_rc,
        "time_ratio_vs_roughconductor": t_kes / t_rc,
        "rmse_importance_sampling_path": rmse["path", "lobe"],
        "rmse_cosine_sampling_path": rmse["path", "cosine"],
        "rmse_ratio_is_vs_cosine": rmse["path", "lobe"] / rmse["path", "cosine"],
        "rmse_importance_sampling_bsdf_only": rmse["bsdf", "lobe"],
        "rmse_cosine_sampling_bsdf_only": rmse["bsdf", "cosine"],
        "rmse_ratio_is_vs_cosine_bsdf_only": rmse["bsdf", "lobe"] / rmse["bsdf", "cosine"],
        "spp": SPP,
        "reference_spp": REF_SPP,
        "resolution": f"{RESOLUTION[0]}x{RESOLUTION[1]}",
    }


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
