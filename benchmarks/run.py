"""Run every benchmarks/bench_*.py and write the results to one JSON file.

Each module exposes ``run() -> dict``.  Absolute times on shared machines are noisy;
compare ratios measured in the same run (they are written side by side).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))
sys.path.insert(0, str(HERE))  # the bench modules share benchmarks/_timing.py


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", default=str(HERE / "results.json"))
    ap.add_argument("--only", nargs="*", help="bench module names (e.g. core render)")
    ap.add_argument("--merge", action="store_true",
                    help="keep the other sections of the output file (with --only: rerun some, keep the rest)")
    args = ap.parse_args()
    from kesbrdf import __version__

    results = {
        "kesbrdf_version": __version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
        "benchmarks": {},
    }

    for path in sorted(HERE.glob("bench_*.py")):
        name = path.stem[len("bench_"):]
        if args.only and name not in args.only:
            continue
        print(f"bench {name} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            results["benchmarks"][name] = module.run()
        except Exception as exc:  # a missing optional part must not hide the others
            results["benchmarks"][name] = {"error": f"{type(exc).__name__}: {exc}"}
            traceback.print_exc()
        print(f"bench {name}: {time.perf_counter() - t0:.1f}s", file=sys.stderr, flush=True)
    if args.merge and Path(args.output).is_file():  # read now: another bench may have merged meanwhile
        kept = dict(json.loads(Path(args.output).read_text()).get("benchmarks", {}))
        results["benchmarks"] = {**kept, **results["benchmarks"]}
    tmp = Path(args.output).with_suffix(".part")
    tmp.write_text(json.dumps(results, indent=1, default=float) + "\n")
    os.replace(tmp, args.output)
    print(f"wrote {args.output}", file=sys.stderr)
    if Path(args.output).resolve() == (HERE / "results.json").resolve():
        import results_page  # the one page of measured numbers, docs/results.md

        results_page.main([])
    return 0


if __name__ == "__main__":
    sys.exit(main())
