"""Real data in by path: time to read and fit each public file ``kesbrdf fit`` takes directly.

For each input (``kesbrdf.io.sources.read_source`` then ``kesbrdf.fit`` with
``kind="auto"``, the held-out comparison included, as ``kesbrdf fit FILE`` runs it):

* CUReT fabrics felt, corduroy, linen, velvet (``$KESBRDF_CURET_DIR`` when set,
  else rebuilt from the committed extract ``tests/data/curet_fabrics.csv``);
* the RGL acrylic felts (``$KESBRDF_RGL_DIR`` when set, else the committed white felt),
  paper protocol, and the white felt at the dense protocol;
* a full-size synthetic MERL ``.binary`` of an isotropic Ward + Lambert BRDF (no MERL
  material is redistributable here; the file has the real size and layout).

Per input: ``<name>_read_cpu_s`` and ``<name>_fit_cpu_s`` (process CPU time, s: the
machine is shared, so CPU time rather than wall time), ``<name>_kind`` (the kind kept)
and ``<name>_rows``.
Run: ``PYTHONPATH=src python benchmarks/bench_sources.py`` (about 3-5 CPU-min).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))  # source_helpers: CUReT / MERL writers

CURET_SAMPLES = ("felt", "corduroy", "linen", "velvet")


def inputs(folder: Path) -> list:
    """(name, path, read_source options) of every input timed."""
    from bench_rgl import felt_paths
    from source_helpers import write_curet, write_merl

    from kesbrdf.io.curet import FABRICS
    from kesbrdf.references.ward import AnisotropicWard

    curet = Path(os.environ.get("KESBRDF_CURET_DIR") or folder / "curet")
    if not (curet / "abrdf.dat").is_file():
        curet = folder / "curet"
        curet.mkdir()
        write_curet(curet, samples=tuple(FABRICS))
    out = [(f"curet_{s}", curet / "abrdf.dat", {"sample": s}) for s in CURET_SAMPLES]
    felts = felt_paths()
    out += [(f"rgl_{name}_paper", path, {}) for name, path in felts.items()]
    out.append(("rgl_white_dense", felts["white"], {"protocol": "dense"}))
    merl = folder / "ward.binary"
    write_merl(merl, AnisotropicWard(0.25, 0.25, rho_d=[0.3, 0.2, 0.1], rho_s=0.15))
    out.append(("merl_synthetic_paper", merl, {}))
    return out


def run() -> dict:
    import kesbrdf
    from kesbrdf.io.sources import read_source

    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, options in inputs(Path(tmp)):
            t0 = time.process_time()
            m = read_source(path, **options)
            t1 = time.process_time()
            _, report = kesbrdf.fit(m)
            t2 = time.process_time()
            res[f"{name}_read_cpu_s"] = round(t1 - t0, 3)
            res[f"{name}_fit_cpu_s"] = round(t2 - t1, 2)
            res[f"{name}_kind"] = report.fitter if report.fitter == "scattered" else report.kind
            res[f"{name}_rows"] = len(m)
            print(f"{name}: read {t1 - t0:.2f} s, fit {t2 - t1:.1f} s CPU, kind {res[f'{name}_kind']}",
                  file=sys.stderr, flush=True)
    return res


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
