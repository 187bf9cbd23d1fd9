"""``kesbrdf demo`` as a whole: wall and CPU time of every step (goal: ≤ 3 minutes warm).

``run()`` runs the full demo (not ``--quick``) into a temporary folder in this process
and returns its ``demo_times.json``: per step the wall time and the CPU time of the
process (all threads), and the totals.  Run it after the drape and render benchmarks
so that Warp's and Dr.Jit's kernel caches are warm.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path


def run() -> dict:
    from kesbrdf.cli.main import main

    with tempfile.TemporaryDirectory(prefix="kesbrdf-bench-demo-") as tmp:
        out = Path(tmp) / "demo"
        code = main(["demo", "-o", str(out)])
        times = json.loads((out / "demo_times.json").read_text())
    result = {"exit_code": code, "total_wall_s": times["total_wall_s"], "total_cpu_s": times["total_cpu_s"]}
    for step in times["steps"]:
        key = step["step"].split(":")[0].strip().replace(" ", "_") + ":" + step["step"].split(":", 1)[-1].strip()[:24]
        result[f"{key} wall_s"] = step["wall_s"]
        result[f"{key} cpu_s"] = step["cpu_s"]
    return result


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    print(json.dumps(run(), indent=1))
