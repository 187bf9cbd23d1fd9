"""Throughput of the reference BRDFs: evaluations per second at 1e5 random pairs.

``run()`` returns a dict of named numbers for ``benchmarks/run.py``. Each model is timed
on the same 1e5 direction pairs, uniform on the upper hemisphere (seeded), and the best
of ``repeats`` runs is reported.
"""

from __future__ import annotations

import time

import numpy as np

N_PAIRS = 100_000
SEED = 7


def _pairs(n: int = N_PAIRS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return v[0], v[1]


def _rate(brdf, wi, wr, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        brdf(wi, wr)
        best = min(best, time.perf_counter() - start)
    return wi.shape[0] / best


def run(repeats: int = 2) -> dict:
    """Evaluations per second of each reference model at 1e5 random pairs."""
    from kesbrdf.references.ashikhmin_shirley import AshikhminShirley
    from kesbrdf.references.sadeghi2013 import Sadeghi2013

    wi, wr = _pairs()
    models = {
        "sadeghi2013_satin_arclength32_reciprocal": Sadeghi2013("satin"),
        "sadeghi2013_satin_arclength32_forward": Sadeghi2013("satin", reciprocal=False),
        "sadeghi2013_satin_control_points": Sadeghi2013("satin", sampling="control_points"),
        "sadeghi2013_linen_arclength32_reciprocal": Sadeghi2013("linen"),
        "ashikhmin_shirley_rgb": AshikhminShirley(10, 100, R_s=0.05, R_d=[0.5, 0.3, 0.2]),
    }
    try:  # the lead's Ward reference, when present
        from kesbrdf.references.ward import AnisotropicWard

        models["ward_anisotropic"] = AnisotropicWard(0.1, 0.3, 0.3, 0.05)
    except Exception:  # noqa: BLE001  (absent or a different signature: skip it)
        pass
    result = {f"{name}_evals_per_s": _rate(brdf, wi, wr, repeats) for name, brdf in models.items()}
    result["n_pairs"] = N_PAIRS
    return result


if __name__ == "__main__":  # pragma: no cover
    for key, value in run().items():
        print(f"{key}: {value:,.0f}")
