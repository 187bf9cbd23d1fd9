"""Real data: KES models of the RGL-EPFL acrylic felts against the measured felts.

For each felt (all three from ``$KESBRDF_RGL_DIR`` when set, else the one
shipped in ``src/kesbrdf/data/rgl``):

* ``<felt>_kes_<mapping>_<light>_{rmse,log_rmse,nrmse}``: the paper-protocol model
  (ψ = 0, 45, 90, 135°, θ_i + θ_r = 90°, 3° steps; ``kesbrdf.models.kes.fit``) read through
  each mapping, on the Fig. 6 hemispheres (light θ_i = 30°, φ_i = 90° or 45°; viewer on
  a 2.5° grid to 87.5°);
* ``<felt>_halfdiff_<light>_...``: the ``kes-halfdiff`` model from the dense protocol
  (6° grid of (θ_i, θ_r) at the four orientations; ``kesbrdf.models.halfdiff.fit_halfdiff``);
* ``<felt>_constant_<light>_...``: the hemisphere's own mean value, a floor any model
  should beat;
* ``<felt>_held_out_max_rel``: max relative error of the paper-protocol model
  (deviation mapping) at ψ = 22.5, 60, 112.5° on the paper line, and
  ``<felt>_line_non_reciprocity``, the data's own max |f(i,r) − f(r,i)|/max there,
  which bounds it (tests/references/test_rgl.py).

rmse in 1/sr; log_rmse and nrmse as :func:`kesbrdf.validate.compare.metrics`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SHARED = Path(os.environ["KESBRDF_RGL_DIR"]) if os.environ.get("KESBRDF_RGL_DIR") else None
COMMITTED = HERE.parent / "src" / "kesbrdf" / "data" / "rgl"
FELTS = ("white", "pink", "purple")
HELD_OUT_DEG = (22.5, 60.0, 112.5)


def felt_paths() -> dict:
    """Felt name -> path of its RGB tensor file (shared data first, else committed)."""
    out = {}
    for name in FELTS:
        for folder in (f for f in (SHARED, COMMITTED) if f is not None):
            path = folder / f"acrylic_felt_{name}_rgb.bsdf"
            if path.exists():
                out[name] = path
                break
    return out


def hemisphere_errors(felt, models: dict) -> dict:
    """{f"{label}_{light}_{metric}": value} over the Fig. 6 hemispheres.

    ``models`` maps a label to a callable f(wi, wr) -> (..., 3)."""
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.validate.compare import HEMISPHERE_LIGHTS_DEG, hemisphere_directions, metrics

    wr, _, _ = hemisphere_directions()
    wr = wr.reshape(-1, 3)
    out = {}
    for theta_i, phi_i in HEMISPHERE_LIGHTS_DEG:
        wi = spherical_to_cartesian(np.radians(theta_i), np.radians(phi_i))[None, :]
        truth = felt(wi, wr)
        light = f"light{theta_i:g}_{phi_i:g}"
        predictions = {label: model(wi, wr) for label, model in models.items()}
        predictions["constant"] = np.broadcast_to(truth.mean(axis=0), truth.shape)
        for label, pred in predictions.items():
            res = metrics(pred, truth)["all"]
            for key in ("rmse", "log_rmse", "nrmse"):
                out[f"{label}_{light}_{key}"] = res[key]
    return out


def run() -> dict:
    from kesbrdf.models.brdf import MAPPINGS, evaluate
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.halfdiff import fit_halfdiff
    from kesbrdf.models.kes import fit
    from kesbrdf.references.rgl import RGLMeasured

    result = {}
    for name, path in felt_paths().items():
        felt = RGLMeasured(path)
        m = measure(felt)
        kes = fit(m)
        halfdiff = fit_halfdiff(measure(felt, protocol="dense", step_deg=6))
        models = {f"kes_{mapping}": (lambda wi, wr, mp=mapping: evaluate(kes, wi, wr, mp)) for mapping in MAPPINGS}
        models["halfdiff"] = lambda wi, wr: evaluate(halfdiff, wi, wr)
        for key, value in hemisphere_errors(felt, models).items():
            result[f"{name}_{key}"] = value
        held = measure(felt, orientations_deg=HELD_OUT_DEG)
        pred = evaluate(kes, held.wi, held.wr, "deviation")
        result[f"{name}_held_out_max_rel"] = float(np.max(np.abs(pred - held.values) / held.values))
        transposed = felt(m.wr, m.wi)
        result[f"{name}_line_non_reciprocity"] = float(
            np.max(np.abs(m.values - transposed) / np.maximum(m.values, transposed))
        )
    result["n_felts"] = len(felt_paths())
    return result


if __name__ == "__main__":  # pragma: no cover
    for key, value in run().items():
        print(f"{key}: {value:.4g}")
