"""Export benchmark: the RGL tensor ``.bsdf`` per grid resolution.

For each grid (θ_i × φ_i × N², NDF resolution, floor ε): file size, writer time, and the
agreement of Mitsuba 3's own ``measured`` ``eval`` with :func:`kesbrdf.models.brdf.evaluate`
(relative error of f_r·cos θ_o on the luminance, median / p90 / p99 and value-weighted,
split grazing (either direction beyond 60°) vs not) at 20 000 random pairs with
cos θ > 0.1, on three fitted fabrics (anisotropic Ward, Sadeghi satin, a narrow
satin-like Ward on a dark body).
``run()`` returns named numbers; run alone with
``PYTHONPATH=src python benchmarks/run.py --only export --output /tmp/export-bench.json``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

#: (name, options) of the grids compared; the default is DEFAULTS of kesbrdf.export.rgl_bsdf
GRIDS = [
    ("9x17x24_ndf32_floor0.05", dict(n_theta_i=9, n_phi_i=17, n=24, n_ndf=32, floor=0.05)),
    ("17x17x32_ndf64_floor0.05", dict(n_phi_i=17, n=32, n_ndf=64, floor=0.05)),
    ("17x33x32_ndf64_floor0.05", dict(n=32, n_ndf=64, floor=0.05)),
    ("17x33x32_ndf64_floor0.01", dict(n=32, n_ndf=64, floor=0.01)),
    ("17x33x32_ndf32_floor0.2", dict(n=32)),
    ("17x33x48_ndf32_floor0.2_default", dict()),
    ("25x33x48_ndf32_floor0.2", dict(n_theta_i=25)),
    ("17x49x48_ndf32_floor0.2", dict(n_phi_i=49)),
    ("17x33x64_ndf32_floor0.2", dict(n=64)),
    ("17x33x48_ndf32_floor0.2_vndf_model", dict(vndf="model")),
]
N_PAIRS = 20000
MIN_COS = 0.1


def _models():
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit
    from kesbrdf.references.sadeghi2013 import Sadeghi2013
    from kesbrdf.references.ward import AnisotropicWard

    return {
        "ward": fit(measure(AnisotropicWard(0.1, 0.3, rho_d=[0.2, 0.1, 0.05], rho_s=0.1))),
        "sadeghi_satin": fit(measure(Sadeghi2013(preset="satin")), fallback="log"),
        # narrow satin-like lobe on a dark body (the CLI's "satin-ward" reference)
        "satin_ward": fit(measure(AnisotropicWard(0.08, 0.22, rho_d=0.02, rho_s=0.12))),
    }


def _pairs(seed=7):
    rng = np.random.default_rng(seed)

    def dirs(k):
        z = rng.uniform(MIN_COS, 1.0, k)
        p = rng.uniform(-np.pi, np.pi, k)
        r = np.sqrt(1 - z * z)
        return np.stack([r * np.cos(p), r * np.sin(p), z], axis=-1)

    return dirs(N_PAIRS), dirs(N_PAIRS)


def mitsuba_agreement(model, path, w_view, w_light) -> dict:
    """Mitsuba ``measured`` eval vs the model (f_r·cos θ_light), luminance relative errors."""
    from kesbrdf.export.rgl_bsdf import LUMINANCE, model_brdf, relative_errors
    from kesbrdf.references.rgl import eval_plugin, load_plugin

    bsdf = load_plugin({"type": "measured", "filename": str(path)})
    got = eval_plugin(bsdf, w_view, w_light) @ LUMINANCE
    want = (model_brdf(model)(w_light, w_view) * w_light[:, 2:3]) @ LUMINANCE
    return relative_errors(got, want, w_view, w_light)


def run() -> dict:
    from kesbrdf.export import export

    out: dict = {"n_pairs": N_PAIRS, "min_cos": MIN_COS}
    w_view, w_light = _pairs()
    with tempfile.TemporaryDirectory() as tmp:
        for mname, model in _models().items():
            for gname, options in GRIDS:
                path = Path(tmp) / f"{mname}_{gname}.bsdf"
                t0 = time.perf_counter()
                result = export(model, "rgl-bsdf", path, check=False, **options)
                seconds = time.perf_counter() - t0
                row = {"size_mib": result.size / 2**20, "writer_s": seconds}
                row.update(mitsuba_agreement(model, path, w_view, w_light))
                out[f"{mname}/{gname}"] = row
                path.unlink()
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
