"""Core benchmarks: BRDF evaluations/s per mapping, fit times, KES vs baselines.

``brdf_vs_copy_*``: the time of ``evaluate`` over the time of ``np.copy`` of its two
input arrays (same pairs), per mapping; ``brdf_peak_memory_1e7``: tracemalloc's peak of
the allocations made inside ``evaluate`` for 1e7 pairs, against the bytes of the
inputs and the output (issue 8 asks for about 2× input + output at most).
"""

from __future__ import annotations

import tracemalloc

import numpy as np

from kesbrdf.models.brdf import MAPPINGS, evaluate
from kesbrdf.geometry import spherical_to_cartesian
from kesbrdf.measure.gonio import measure
from kesbrdf.models.kes import fit
from kesbrdf.references.ward import AnisotropicWard
from kesbrdf.validate.compare import compare_reference

from _timing import best_of

#: References for the KES-vs-baselines ratio: a spread of lobe widths and
#: anisotropies, not one material.
REFERENCES = {
    "ward_0.10_0.20": AnisotropicWard(0.10, 0.20, rho_d=[0.3, 0.2, 0.1], rho_s=0.1),
    "ward_0.12_0.30": AnisotropicWard(0.12, 0.30, rho_d=[0.25, 0.2, 0.15], rho_s=0.15),
    "ward_0.20_0.40": AnisotropicWard(0.20, 0.40, rho_d=0.2, rho_s=0.1),
    "ward_satin_0.08_0.22": AnisotropicWard(0.08, 0.22, rho_d=0.02, rho_s=0.12),
    "ward_narrow_0.05_0.10": AnisotropicWard(0.05, 0.10, rho_d=0.02, rho_s=0.1),
}




def peak_memory(model, n: int = 10_000_000) -> dict:
    """Peak bytes allocated inside ``evaluate`` for ``n`` random pairs (tracemalloc)."""
    rng = np.random.default_rng(5)
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    f = evaluate(model, wi, wr)
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    io_bytes = wi.nbytes + wr.nbytes + f.nbytes
    return {
        "brdf_peak_memory_1e7_bytes": int(peak),
        "brdf_io_bytes_1e7": int(io_bytes),
        "brdf_peak_over_io_1e7": peak / io_bytes,
    }


def run() -> dict:
    rng = np.random.default_rng(0)
    ref = REFERENCES["ward_0.10_0.20"]
    m = measure(ref, noise=0.01, rng=1)
    model = fit(m)
    n = 200_000
    wi = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    wr = spherical_to_cartesian(np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n))
    out = {}
    t_copy = best_of(lambda: (np.copy(wi), np.copy(wr)), 5)
    for mapping in MAPPINGS:
        t = best_of(lambda: evaluate(model, wi, wr, mapping), 3)
        out[f"brdf_evals_per_s_{mapping}"] = n / t
        out[f"brdf_vs_copy_{mapping}"] = t / t_copy
    out.update(peak_memory(model))
    t_ref = best_of(lambda: ref(wi, wr), 3)
    out["brdf_evals_per_s_ward_reference"] = n / t_ref
    out["fit_s_paper_116"] = best_of(lambda: fit(m), 5)
    dense = measure(ref, protocol="dense", step_deg=6, noise=0.01, rng=2)
    out["dense_samples"] = len(dense)
    out["fit_s_dense_rgb"] = best_of(lambda: fit(dense), 5)
    try:
        from kesbrdf.models.halfdiff import fit_halfdiff

        out["fit_s_dense_rgb_halfdiff"] = best_of(lambda: fit_halfdiff(dense), 2)
    except ImportError:
        pass
    ratios = {}
    for name, reference in REFERENCES.items():
        r = compare_reference(measure(reference, noise=0.01, rng=3), reference, fallback="log")
        ratios[name] = r["ratio_kes_to"]
    out["kes_rmse_over_baseline_rmse"] = ratios
    return out
