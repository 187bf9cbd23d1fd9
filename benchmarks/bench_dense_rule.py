"""The dense rule with and without its difference-angle hold-out (eq. D2), per fabric (issue 20).

For each fabric: the paper protocol's default fit (116 samples) and the dense protocol's
(900), both 2 % noise, scored on the Fig. 6 hemispheres against the noise-free reference
(:func:`kesbrdf.validate.lofo.score`).  The dense fit is ``kesbrdf.fit`` as it is (the new
rule); the old rule's kind is :func:`kesbrdf.validate.selection.choose_dense` without the
bands on the same comparison, and when it differs that kind is fitted and scored too.

    python benchmarks/bench_dense_rule.py --library out/library --per-family 3 --seed 0
    python benchmarks/bench_dense_rule.py            # lofo.family_library(draws=3), bench_lofo's seeds

Prints one JSON line per fabric and a Markdown table (docs/decisions.md, "The dense rule
holds out a difference-angle band too", has the measured tables).  About 20-40 CPU s per
fabric; one process.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent / "src") not in sys.path:
    sys.path.insert(0, str(HERE.parent / "src"))

from kesbrdf.validate import lofo  # noqa: E402


def cases(library=None, per_family=3, seed=0, draws=3):
    """(family, fabric, reference, paper measurement, dense measurement, truths)."""
    if library is not None:
        from kesbrdf.validate.library import load_library

        built = load_library(library)
        refs = lofo.family_library_from(built, per_family=per_family, seed=seed)
        data = lofo.library_inputs(built, refs)
        for fam, fabs in refs.items():
            for name, ref in fabs.items():
                d = data[fam][name]
                yield fam, name, ref, d["paper"], d["dense"], d["tests"]
        return
    from kesbrdf.measure.gonio import measure

    for k, (fam, fabs) in enumerate(lofo.family_library(draws=draws).items()):
        for j, (name, ref) in enumerate(fabs.items()):  # run_lofo's seeds: 1000 k + 10 j + protocol
            yield (fam, name, ref, measure(ref, protocol="paper", noise=lofo.NOISE, rng=1000 * k + 10 * j),
                   measure(ref, protocol="dense", noise=lofo.NOISE, rng=1000 * k + 10 * j + 1), lofo.scoring_truths(ref))


def row(fam, name, ref, paper, dense, tests) -> dict:
    from kesbrdf.fitting import DENSE_KES_BRANCH, fit
    from kesbrdf.models.base import fitter_class
    from kesbrdf.validate.selection import choose_dense

    hemi = lambda model: lofo.score(model.evaluate, ref, tests)["hemispheres"]  # noqa: E731
    out = {"family": fam, "fabric": name, "paper_hemi": hemi(fit(paper)[0])}
    c0 = time.process_time()
    model, report = fit(dense)
    out.update(new_kind=report.fitter, dense_cpu_s=time.process_time() - c0, new_hemi=hemi(model))
    c = report.comparison or {}
    out["old_kind"] = choose_dense(c, DENSE_KES_BRANCH)[0] if c else report.fitter
    out["old_hemi"] = out["new_hemi"] if out["old_kind"] == out["new_kind"] else \
        hemi(fitter_class(out["old_kind"]).fit_measurement(dense))
    out["bands_log_sse"] = (c.get("bands") or {}).get("log_sse")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--library", default=None)
    ap.add_argument("--per-family", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--draws", type=int, default=3)
    args = ap.parse_args(argv)
    rows = []
    for case in cases(args.library, args.per_family, args.seed, args.draws):
        rows.append(row(*case))
        print(json.dumps(rows[-1], default=float), flush=True)
    print("| fabric | paper | dense, old rule | dense, new rule | new / paper | CPU s |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['fabric']} | {r['paper_hemi']:.3f} | {r['old_kind']} {r['old_hemi']:.3f} | "
              f"{r['new_kind']} {r['new_hemi']:.3f} | {r['new_hemi'] / r['paper_hemi']:.2f} | {r['dense_cpu_s']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
