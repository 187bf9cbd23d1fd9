"""Batch throughput: fabrics per minute for fit + validate + export (ingest included).

* ``serial``: :func:`kesbrdf.batch.runner.run_fabric` for every fabric, one after the
  other in this process (no Dask): the same steps, manifests and files.
* ``dask_1`` / ``dask_2``: :func:`kesbrdf.batch.run_batch` on an already running
  LocalCluster of 1 and 2 spawned worker processes (start-up timed separately).

Scaling efficiency = (t_1 / t_2) / 2; per-task overhead = t_1 / t_serial − 1.  Every run
writes into a fresh folder (a rerun would skip everything).  The fabrics are the
synthetic library (Sadeghi presets, Ward, Ashikhmin–Shirley) as measurement CSVs.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

N_FABRICS = 48
STEPS = ("fit", "validate", "export")


def _serial(fabrics, out):
    from kesbrdf.batch.runner import run_fabric
    from kesbrdf.batch.steps import closure
    from kesbrdf.batch.store import Store

    store = Store(out)
    t0 = time.perf_counter()
    for f in fabrics:
        run_fabric(f, store, closure(STEPS))
    return time.perf_counter() - t0


def run() -> dict:
    from distributed import Client

    from kesbrdf.batch import read_catalog, run_batch
    from kesbrdf.batch.engine import start_local_cluster
    from kesbrdf.batch.library import simulate_library

    root = Path(tempfile.mkdtemp(prefix="kesbrdf-bench-batch-"))
    catalog = simulate_library(N_FABRICS, root / "lib", seed=1, broken=0, images_every=0)
    fabrics = read_catalog(catalog)
    _serial(fabrics[:4], root / "warm")  # imports and first-call costs out of the timings
    t_serial = min(_serial(fabrics, root / f"serial{k}") for k in range(2))
    res = {"n_fabrics": N_FABRICS, "steps": list(STEPS), "cpus": os.cpu_count(),
           "serial_s": t_serial, "serial_fabrics_per_min": N_FABRICS / t_serial * 60}
    for n in (1, 2):
        t0 = time.perf_counter()
        cluster = start_local_cluster(n, render=False)
        client = Client(cluster)
        res[f"dask_{n}_startup_s"] = time.perf_counter() - t0
        try:
            run_batch(fabrics[:4], root / f"warm{n}", steps=STEPS, scheduler=client, write_summary=False)
            times = []
            for k in range(2):
                t0 = time.perf_counter()
                r = run_batch(fabrics, root / f"dask{n}_{k}", steps=STEPS, scheduler=client, write_summary=False)
                times.append(time.perf_counter() - t0)
                assert r.counts["done"] == N_FABRICS, r.counts
        finally:
            client.close()
            cluster.close()
        res[f"dask_{n}_s"] = min(times)
        res[f"dask_{n}_fabrics_per_min"] = N_FABRICS / min(times) * 60
    res["scaling_efficiency_2"] = res["dask_1_s"] / res["dask_2_s"] / 2
    res["overhead_vs_serial"] = res["dask_1_s"] / t_serial - 1
    res["per_fabric_serial_ms"] = t_serial / N_FABRICS * 1e3
    res["per_task_overhead_ms"] = (res["dask_1_s"] - t_serial) / N_FABRICS * 1e3
    res["load_average_1min"] = os.getloadavg()[0]
    import shutil

    shutil.rmtree(root, ignore_errors=True)
    return res


if __name__ == "__main__":  # pragma: no cover
    import json

    print(json.dumps(run(), indent=1))
