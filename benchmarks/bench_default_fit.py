"""CPU time of the default fit (``kesbrdf.fitting.fit(m)``, its kind comparison included) on one core.

Issue 20's budget: at most 5 CPU s for the paper protocol's 116 samples and 30 CPU s for
the dense protocol's 900, on one core.  Measured here on the four measurements the budget
was set on: the embedded demo sample (what ``kesbrdf demo`` ingests), the virtual
paper-protocol measurements of the Sadeghi black satin and of Irawan's cotton twill, and
the dense measurement of the black satin (``kesbrdf.measure.gonio.measure``).  Each fit
runs ``REPEATS`` times in this process with BLAS held to one thread (threadpoolctl) and
the smallest CPU time is kept (the least disturbed by other jobs on the machine).

Absolute CPU seconds on a shared machine move with its load, so each is also given as a
ratio to ``reference_cpu_s``: a fixed workload of the same character (small NumPy array
operations and Python scalar arithmetic, as in the prior's fits), timed in the same run,
before and after the fits (the smaller of the two).  The fits' results do not depend on
any of this: ``kind`` is the kind chosen and ``checksum`` the sum of the model's values
on the measured samples, to compare runs.

Run alone with ``PYTHONPATH=src python benchmarks/run.py --only default_fit --output /tmp/df.json``.
"""

from __future__ import annotations

import contextlib
import sys
import time

import numpy as np

#: Repeats of each fit; the smallest CPU time is reported.
REPEATS = 2
#: Issue 20's budget, CPU seconds on one core.
BUDGET_S = {"paper": 5.0, "dense": 30.0}


def _measurements() -> dict:
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.measure import demo_data
    from kesbrdf.measure.gonio import measure
    from kesbrdf.references.irawan2012 import Irawan2012
    from kesbrdf.references.sadeghi2013 import black_satin

    return {
        "demo_sample": ("paper", read_measurement(demo_data.embedded_measurement())),
        "black_satin_paper": ("paper", measure(black_satin(), protocol="paper")),
        "irawan_cotton_twill_paper": ("paper", measure(Irawan2012("cotton_twill"), protocol="paper")),
        "black_satin_dense": ("dense", measure(black_satin(), protocol="dense")),
    }


def reference_workload() -> float:
    """CPU seconds of a fixed workload like a prior fit's (small arrays, many calls)."""
    rng = np.random.default_rng(0)
    a = rng.uniform(0.1, 1.0, size=(1, 116, 32))
    J = rng.normal(size=(348, 17))
    x = rng.normal(size=17)
    c0 = time.process_time()
    acc = 0.0
    for k in range(6000):
        t = np.arccos(np.clip(a * 0.9, -1.0, 1.0)) + np.sin(a) * np.cos(a)
        t = np.where(t > 1.0, t - 1.0, t) / np.maximum(a, 1e-9)
        y = J.dot((x * 0.5).reshape(-1, 1)).reshape(348)
        acc += float(np.sqrt(y.dot(y))) + float(t.sum()) * 1e-9 + (k % 7) * 0.5 / (1.0 + k)
    return time.process_time() - c0


def _one_thread():
    # the BLAS libraries must be loaded before the limit is set (threadpoolctl limits the
    # loaded ones): numpy's, and scipy's own, which the fitters import on first use
    import scipy.linalg  # noqa: F401
    import scipy.optimize  # noqa: F401

    from kesbrdf.models import fibre_coord, fibre_physics  # noqa: F401

    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # threadpoolctl comes with kesbrdf[export]; without it, OPENBLAS_NUM_THREADS=1
        return contextlib.nullcontext()
    return threadpool_limits(limits=1)


def run() -> dict:
    from kesbrdf.fitting import fit

    out: dict = {}
    with _one_thread():
        ref = [reference_workload()]
        for name, (protocol, m) in _measurements().items():
            cpu = []
            for _ in range(REPEATS):
                c0 = time.process_time()
                model, report = fit(m)
                cpu.append(time.process_time() - c0)
            best = min(cpu)
            out[name] = {
                "protocol": protocol, "samples": len(m), "kind": report.kind, "cpu_s": best,
                "within_budget": bool(best <= BUDGET_S[protocol]),
                "checksum": float(np.sum(model.evaluate(m.wi, m.wr))),
            }
            print(f"bench default_fit: {name} ({len(m)} samples) kind {report.kind}: {best:.2f} s CPU "
                  f"(budget {BUDGET_S[protocol]:g} s)", file=sys.stderr, flush=True)
        ref.append(reference_workload())
    reference = min(ref)
    for row in out.values():
        row["ratio_to_reference"] = row["cpu_s"] / reference
    out["reference_cpu_s"] = reference
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
