"""CPU seconds of the default fit (``kesbrdf.fit(m)``, its kind comparison included) per fabric.

Issue 20's budget: at most 5 CPU s for the paper protocol's 116 samples and 30 CPU s for
the dense protocol's 900, on one core.  benchmarks/bench_default_fit.py times the four
noise-free measurements the budget was set on; this one times the fabrics the default is
judged on: the 12 of :func:`kesbrdf.validate.lofo.family_library` (``draws=3``; Irawan,
Sadeghi, Ward, Ashikhmin–Shirley) simulated as benchmarks/bench_extras.py does (2 %
noise, seed 100·family + fabric), plus the embedded demo sample and the Sadeghi black
satin and Irawan cotton twill at 2 % noise, seed 0, each with the paper protocol
(116 samples) and, except the demo sample, the dense one (900).  One BLAS thread
(threadpoolctl), one fit per measurement, ``time.process_time``.

Besides the seconds each row has the kept kind, how many prior fits the kind comparison
skipped (``kesbrdf.validate.selection.loo_compare(decide=True)``) and the hemisphere
NRMSE of :func:`kesbrdf.validate.lofo.score`, so a faster fit that returns something
else shows here.  ``PYTHONPATH=src python benchmarks/run.py --only fit_speed --output /tmp/fs.json``;
``--paper-only`` when run as a script skips the dense protocol (a few minutes of CPU).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys
import time

import numpy as np

#: Issue 20's budget, CPU seconds on one core.
BUDGET_S = {"paper": 5.0, "dense": 30.0}
FAMILIES = ("irawan2012", "sadeghi2013", "ward", "ashikhmin_shirley")
DRAWS = 3
NOISE = 0.02


def fabrics() -> dict:
    """{name: (reference or None, seed)}: the named three and the library's twelve."""
    from kesbrdf.references.irawan2012 import Irawan2012
    from kesbrdf.references.sadeghi2013 import black_satin
    from kesbrdf.validate import lofo

    out = {"demo_sample": (None, None), "sadeghi_black_satin": (black_satin(), 0),
           "irawan_cotton_twill": (Irawan2012("cotton_twill"), 0)}
    library = lofo.family_library(draws=DRAWS, families=FAMILIES)
    for k, (fam, refs) in enumerate(library.items()):
        for j, (name, ref) in enumerate(refs.items()):
            out[f"{fam}/{name}"] = (ref, 100 * k + j)
    return out


def _measurement(ref, seed, protocol):
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.measure import demo_data, planning

    if ref is None:
        return read_measurement(demo_data.embedded_measurement()) if protocol == "paper" else None
    return planning.simulate(ref, (protocol,), noise=NOISE, rng=seed)


def _one_thread():
    import contextlib

    import scipy.linalg  # noqa: F401  (load the BLAS libraries before limiting them)
    import scipy.optimize  # noqa: F401

    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # then OPENBLAS_NUM_THREADS=1 above
        return contextlib.nullcontext()
    return threadpool_limits(limits=1)


def run(protocols=("paper", "dense")) -> dict:
    from kesbrdf.fitting import fit
    from kesbrdf.references.sadeghi2013 import black_satin
    from kesbrdf.validate import lofo

    rows: dict = {}
    with _one_thread():
        for name, (ref, seed) in fabrics().items():
            truth = black_satin() if ref is None else ref  # the demo sample is the virtual black satin
            tests = lofo.scoring_truths(truth)
            for protocol in protocols:
                m = _measurement(ref, seed, protocol)
                if m is None:
                    continue
                c0 = time.process_time()
                model, report = fit(m)
                cpu = time.process_time() - c0
                comparison = report.comparison or {}
                rows.setdefault(name, {})[protocol] = {
                    "samples": len(m), "cpu_s": cpu, "within_budget": bool(cpu <= BUDGET_S[protocol]),
                    "kind": model.kind, "skipped_folds": list(comparison.get("skipped", [])),
                    "hemispheres": lofo.score(model.evaluate, truth, tests)["hemispheres"],
                }
                print(f"bench fit_speed: {name} {protocol} ({len(m)}) {model.kind}: {cpu:.2f} s CPU", file=sys.stderr,
                      flush=True)
    summary = {}
    for protocol in protocols:
        cpu = [r[protocol]["cpu_s"] for r in rows.values() if protocol in r]
        if cpu:
            summary[protocol] = {"n": len(cpu), "median_cpu_s": float(np.median(cpu)), "max_cpu_s": float(np.max(cpu)),
                                 "over_budget": sorted(k for k, r in rows.items()
                                                       if protocol in r and not r[protocol]["within_budget"])}
    return {"fabrics": rows, "summary": summary, "budget_s": BUDGET_S, "noise": NOISE}


if __name__ == "__main__":
    import json

    print(json.dumps(run(("paper",) if "--paper-only" in sys.argv else ("paper", "dense")), indent=1))
