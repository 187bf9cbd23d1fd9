"""Timing helper shared by the benchmark modules (not a benchmark itself)."""

from __future__ import annotations

import time


def best_of(fn, repeats: int = 3) -> float:
    """Smallest wall time of ``repeats`` calls of ``fn`` (least disturbed by other load), s."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best
