"""Acquisition benchmark: frames per second that ingest (and the virtual camera) process.

``run()`` returns named numbers; ``benchmarks/run.py`` collects every ``bench_*.py``.
Run alone with ``PYTHONPATH=src python benchmarks/bench_acquisition.py``.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from _timing import best_of




def run() -> dict:
    from kesbrdf.measure.acquisition import embedded_manifest, ingest, simulate_images
    from kesbrdf.measure.acquisition.manifest import read_manifest
    from kesbrdf.references.sadeghi2013 import black_satin

    results: dict = {}
    embedded = embedded_manifest()
    n_embedded = len(read_manifest(embedded).rows)
    seconds = best_of(lambda: ingest(embedded))
    results["ingest_embedded_frames"] = n_embedded
    results["ingest_embedded_fps"] = n_embedded / seconds  # 24x24 16-bit RGB TIFF

    brdf = black_satin()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "frames"
        sim_seconds = best_of(lambda: simulate_images(brdf, folder, protocol="paper", size=128, margin=8, roi_inset=4, seed=1), repeats=1)
        manifest = folder / "manifest.csv"
        n = len(read_manifest(manifest).rows)
        results["simulate_128px_fps"] = n / sim_seconds
        results["ingest_128px_fps"] = n / best_of(lambda: ingest(manifest), repeats=2)

        big = Path(tmp) / "big"
        simulate_images(brdf, big, protocol="paper", step_deg=30.0, size=512, margin=128, roi_inset=64, seed=1)
        n_big = len(read_manifest(big / "manifest.csv").rows)
        results["ingest_512px_fps"] = n_big / best_of(lambda: ingest(big / "manifest.csv"), repeats=2)

        # end-to-end error of the embedded chain against the reference
        m = ingest(embedded).measurement
        reference = brdf(m.wi, m.wr)
        rel = np.abs(m.values / reference - 1)
        results["embedded_ingest_max_rel_error"] = float(rel.max())
        results["embedded_ingest_rms_rel_error"] = float(np.sqrt(np.mean(rel**2)))
        results["embedded_ingest_max_abs_z"] = float(np.max(np.abs(m.values - reference) / m.uncertainty))
    results.update(compare_with_reference(m, brdf))
    return results


def _rel_l2(model_values, reference, weight=1.0) -> float:
    return float(np.sqrt(np.sum(weight * (model_values - reference) ** 2) / np.sum(weight * reference**2)))


def compare_with_reference(measurement, brdf) -> dict:
    """KES from the four ingested orientations against the reference, and baselines.

    Relative L2 errors (√(Σ(model − ref)²) / √(Σ ref²), over all RGB channels):

    * ``heldout_inplane``: the paper's θ_i + θ_r = 90° line at the orientations
      ψ = 7.5°, 15°, … (every 7.5° except the measured 0/45/90/135°);
    * ``hemi_phi_i_90`` / ``hemi_phi_i_45``: the viewing hemisphere (θ_r < 80°, 2° × 3°
      grid, weighted by the projected solid angle cos θ_r dω) for a light at θ_i = 30°
      and φ_i = 90° or 45° (the paper's Fig. 6).

    Models: ``kes4`` (default), ``kes3`` (the paper's eq. 1–2), and the baselines
    ``nearest`` and ``linear`` (interpolation over φ), each with the deviation and
    half-vector mappings; the log fallback where K(φ) ≤ 0 (docs/method.md, "Interpolation over orientation").
    """
    from kesbrdf.models.brdf import evaluate
    from kesbrdf.geometry import spherical_to_cartesian
    from kesbrdf.measure.gonio import measure
    from kesbrdf.models.kes import fit

    psi_deg = [p for p in np.arange(7.5, 180, 7.5) if p % 45]
    held = measure(brdf, "paper", orientations_deg=psi_deg)
    theta_r, phi_r = np.meshgrid(np.radians(np.arange(1, 80, 2.0)), np.radians(np.arange(0, 360, 3.0)), indexing="ij")
    wr = spherical_to_cartesian(theta_r, phi_r)
    weight = (np.sin(theta_r) * np.cos(theta_r))[..., None]
    lights = {p: np.broadcast_to(spherical_to_cartesian(np.radians(30.0), np.radians(p)), wr.shape) for p in (90, 45)}
    references = {p: brdf(wi, wr) for p, wi in lights.items()}
    models = {
        "kes4": dict(orientations=4),
        "kes3": dict(orientations=3),
        "nearest": dict(interpolation="nearest"),
        "linear": dict(interpolation="linear"),
    }
    out = {}
    for name, kwargs in models.items():
        model = fit(measurement, fallback="log", **kwargs)
        for mapping in ("deviation", "halfvector"):
            key = f"{name}_{mapping}"
            out[f"heldout_inplane_rel_l2_{key}"] = _rel_l2(evaluate(model, held.wi, held.wr, mapping=mapping), held.values)
            for p, wi in lights.items():
                values = evaluate(model, wi, wr, mapping=mapping)
                out[f"hemi_phi_i_{p}_rel_l2_{key}"] = _rel_l2(values, references[p], weight)
    return out


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
