"""What the batch's safety measures cost (docs/batch.md "Inputs that block, steps that hang").

* the step process: one start, and one pickle round trip per step
  (:mod:`kesbrdf.batch.isolation`);
* fsync: one file + its folder, on the file system of the temp folder
  (:mod:`kesbrdf._atomic`, the batch's folder commit);
* a serial batch of ``N_FABRICS`` fabrics (fit + validate + export to ``brdf-explorer``),
  first run and rerun (every output re-hashed), with the step process
  (``task_timeout=600``) and in-process (``task_timeout=0``), interleaved ``REPEATS``
  times, best kept;
* a catalogue with a FIFO input: seconds until the run has written its summary (the
  code before the fix never finished).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

N_FABRICS = 12
REPEATS = 2
SETTINGS = {"export": {"formats": ["brdf-explorer"]}}
STEPS = ("fit", "validate", "export")


def _round_trip(n: int = 500) -> dict:
    from kesbrdf.batch import isolation

    sp = isolation.StepProcess()
    t0 = time.perf_counter()
    sp.start()
    start = time.perf_counter() - t0
    sp.call(abs, (-1,), 60)
    t0 = time.perf_counter()
    for k in range(n):
        sp.call(abs, (-k,), 60)
    per_call = (time.perf_counter() - t0) / n
    sp.close()
    return {"start_s": start, "round_trip_ms": per_call * 1e3}


def _fsync(folder: Path, n: int = 50) -> dict:
    from kesbrdf._atomic import fsync_dir, fsync_file

    t0 = time.perf_counter()
    for k in range(n):
        p = folder / f"f{k}"
        p.write_bytes(b"x" * 4096)
        fsync_file(p)
        fsync_dir(folder)
    return {"file_and_folder_ms": (time.perf_counter() - t0) / n * 1e3}


def run() -> dict:
    from kesbrdf.batch import run_batch
    from kesbrdf.batch.library import simulate_library

    root = Path(tempfile.mkdtemp(prefix="kesbrdf-bench-safety-"))
    try:
        res = {"n_fabrics": N_FABRICS, "steps": list(STEPS), "load_average_1min": os.getloadavg()[0]}
        res["step_process"] = _round_trip()
        (root / "fs").mkdir()
        res["fsync"] = _fsync(root / "fs")
        cat = simulate_library(N_FABRICS, root / "lib", seed=3, broken=0, images_every=4)
        best: dict = {}
        for rep in range(REPEATS):
            for mode, timeout in (("step_process", 600.0), ("in_process", 0)):
                out = root / f"out-{mode}-{rep}"
                t0 = time.perf_counter()
                run_batch(str(cat), out, steps=STEPS, workers=0, settings=SETTINGS, task_timeout=timeout)
                first = time.perf_counter() - t0
                t0 = time.perf_counter()
                again = run_batch(str(cat), out, steps=STEPS, workers=0, settings=SETTINGS, task_timeout=timeout)
                rerun = time.perf_counter() - t0
                assert again.counts["skipped"] == N_FABRICS
                b = best.setdefault(mode, {"first_s": first, "rerun_s": rerun})
                b["first_s"], b["rerun_s"] = min(b["first_s"], first), min(b["rerun_s"], rerun)
        res["serial_batch"] = best
        if hasattr(os, "mkfifo"):
            os.mkfifo(root / "lib" / "pipe.csv")
            fifo_cat = root / "lib" / "fifo.csv"
            fifo_cat.write_text("id,input\nfabric-001,fabric-001.csv\npipe,pipe.csv\n")
            t0 = time.perf_counter()
            r = run_batch(str(fifo_cat), root / "out-fifo", steps=("fit",), workers=0)
            res["fifo_catalog"] = {"seconds_to_summary": time.perf_counter() - t0, "counts": r.counts,
                                   "error": next(x["error"] for x in r.records if x["id"] == "pipe")}
        return res
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    import json
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "src"))
    print(json.dumps(run(), indent=1, default=float))
