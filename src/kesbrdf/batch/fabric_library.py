"""Build the synthetic fabric library on the batch engine (``kesbrdf simulate --fabric-library N``).

The library's content is :mod:`kesbrdf.validate.library` (N seeded fabrics from five
physical families, their simulated measurements and noise-free truths).  This module
splits it into shards of ``shard_size`` fabrics, runs the shards that are not yet
built as tasks on a local Dask cluster (:func:`kesbrdf.batch.engine.run_tasks`: spawned
single-threaded worker processes) or serially (``workers=0``), and writes
``manifest.json`` last.

Caching: a shard whose JSON records the same key (format, version, seed, families,
range) and whose ``.npz`` still has the recorded sha256 is kept, so an interrupted
build resumes and a finished one returns at once.  Shard files of another plan (another
N or shard size) are removed at the end.  The content sha256 does not depend on the
shard size, the number of workers or the order the shards finished in
(:func:`kesbrdf.validate.library.library_sha256`).
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

from kesbrdf._atomic import write_text
from kesbrdf.batch.engine import run_tasks
from kesbrdf.errors import KesbrdfError
from kesbrdf.validate import library as lib

__all__ = ["build_fabric_library", "DEFAULT_SHARD_SIZE", "plan_shards"]

#: Fabrics per shard: ~3-5 s of work (about 0.07 CPU s a fabric, woven families
#: 0.1-0.25 s), few enough files for 2,000 fabrics (40), many enough tasks for two workers.
DEFAULT_SHARD_SIZE = 50
_SHARD_FILE = re.compile(r"^shard-\d{6}-\d{6}\.(npz|json)$")


def plan_shards(n: int, shard_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering 0 ≤ k < n in runs of ``shard_size``.

    >>> plan_shards(7, 3)
    [(0, 3), (3, 6), (6, 7)]
    """
    return [(a, min(a + shard_size, n)) for a in range(0, n, shard_size)]


def _check(n, seed, shard_size, workers) -> None:
    for flag, value, lo in (("--fabric-library", n, 1), ("--seed", seed, 0), ("--shard-size", shard_size, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise KesbrdfError(f"{flag}: expected an integer >= {lo}, got {value!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 0):
        raise KesbrdfError(f"--workers: expected a count >= 0, got {workers!r}")


def build_fabric_library(out, n: int, seed: int = 0, families=lib.LIBRARY_FAMILIES,
                         shard_size: int = DEFAULT_SHARD_SIZE, workers: int | None = 2, scheduler=None,
                         retries: int = 2, progress=None) -> dict:
    """Build (or finish, or confirm) the library of ``n`` fabrics in folder ``out``.

    Parameters
    ----------
    out : path
        The library folder (created).
    n, seed, families
        What the library holds (:mod:`kesbrdf.validate.library`).
    shard_size : int
        Fabrics per shard (one task each).
    workers : int or None
        Local Dask worker processes (default 2); 0 builds serially here; None: one per core.
    scheduler : str or distributed.Client, optional
        An existing cluster instead of a local one.
    progress : callable(event: dict), optional
        ``{"event": "start", "fabrics", "shards", "cached", "workers"}``, then per built
        shard ``{"event": "shard", "done", "total", "fabrics"}`` (fabrics done so far).

    Returns
    -------
    dict
        The manifest of ``out/manifest.json`` (``sha256``: the content hash; ``build``:
        wall and CPU seconds, workers, shards built and cached by the run that wrote it)
        and ``run``: the same numbers for this call.  A call that builds nothing leaves
        the manifest as it was.
    """
    _check(n, seed, shard_size, workers)
    families = lib.check_families(families)
    t0, c0 = time.perf_counter(), time.process_time()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    geom_path = out / "geometry.npz"
    if not geom_path.is_file() or _geometry_changed(geom_path):
        lib.write_geometry(out)
    plan = plan_shards(n, shard_size)
    docs: dict[tuple[int, int], dict] = {}
    for a, b in plan:
        doc = lib.shard_valid(out, seed, families, a, b)
        if doc is not None:
            docs[(a, b)] = doc
    todo = [s for s in plan if s not in docs]
    state = {"fabrics": sum(b - a for a, b in docs), "done": 0, "workers": 0}

    def on_event(ev):
        if ev["event"] == "start":
            state["workers"] = ev["workers"]
        if progress is None:
            return
        if ev["event"] == "start":
            progress({"event": "start", "fabrics": n, "shards": len(plan), "cached": len(docs),
                      "workers": ev["workers"]})
        else:
            a, b = todo[ev["index"]]
            state["fabrics"] += b - a
            state["done"] += 1
            progress({"event": "shard", "done": state["done"], "total": len(todo), "fabrics": state["fabrics"]})

    if todo:
        tasks = [(str(out), seed, families, a, b) for a, b in todo]
        results = run_tasks(lib.build_shard, tasks, workers=workers, scheduler=scheduler, retries=retries,
                            progress=on_event, name="fabric-library")
        for s, doc in zip(todo, results):
            docs[s] = doc
    elif progress:
        progress({"event": "start", "fabrics": n, "shards": len(plan), "cached": len(docs), "workers": 0})
    fabrics = [f for s in plan for f in docs[s]["fabrics"]]
    if [f["index"] for f in fabrics] != list(range(n)):  # pragma: no cover - a shard of another plan
        raise KesbrdfError(f"fabric library {out}: the shards do not cover fabrics 0..{n - 1} in order")
    head = lib.header(seed, n, families)
    sha = lib.library_sha256(head, [f["digest"] for f in fabrics])
    run = {
        "seconds": time.perf_counter() - t0,
        "cpu_seconds_driver": time.process_time() - c0,
        "cpu_seconds_shards": sum(docs[s]["cpu_seconds"] for s in todo),
        "shards_built": len(todo), "shards_cached": len(plan) - len(todo), "shard_size": shard_size,
        "workers": state["workers"],
    }
    old = _read_manifest(out / "manifest.json")
    if not todo and old is not None and old.get("sha256") == sha and old.get("shards") == _shard_list(plan, docs):
        # nothing built: the manifest of the build that made these shards stays as it was
        return {**old, "run": run}
    manifest = {
        **head,
        "sha256": sha,
        "geometry": "geometry.npz",
        "arrays": {name: dtype for name, dtype in lib.ARRAYS},
        "shards": _shard_list(plan, docs),
        # this build; cpu_seconds_all_shards: the compute of every shard, built now or before
        "build": {**run, "cpu_seconds_all_shards": sum(docs[s]["cpu_seconds"] for s in plan)},
        "fabrics": fabrics,
    }
    write_text(out / "manifest.json", json.dumps(manifest, indent=1) + "\n")
    keep = {docs[s]["file"] for s in plan} | {Path(docs[s]["file"]).with_suffix(".json").name for s in plan}
    for p in out.iterdir():
        if _SHARD_FILE.match(p.name) and p.name not in keep:
            p.unlink()
    return {**manifest, "run": run}


def _shard_list(plan, docs) -> list:
    return [{"file": docs[s]["file"], "start": s[0], "stop": s[1], "sha256": docs[s]["sha256"]} for s in plan]


def _read_manifest(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _geometry_changed(path: Path) -> bool:
    import numpy as np

    try:
        with np.load(path) as z:
            old = {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return True
    new = lib.geometry()
    return set(old) != set(new) or any(not np.array_equal(old[k], new[k]) for k in new)
