"""The fabric library built on the batch engine's Dask cluster is rebuilt bit-identically.

Tolerances: none.  Fabric k is a pure function of (seed, k) (its own SeedSequence
child) and every worker is single-threaded with single-threaded BLAS, so 40 fabrics
built as 6 shards on 2 worker processes and as 4 shards serially in this process hash
to the same content sha256 and hold equal arrays.  Uses the session's LocalCluster
(tests/batch/conftest.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from kesbrdf.batch.fabric_library import build_fabric_library
from kesbrdf.validate.library import LIBRARY_FAMILIES, load_library

N = 40


def test_rebuild_is_bit_identical_across_workers_and_shard_sizes(cluster, tmp_path):
    events = []
    on_dask = build_fabric_library(tmp_path / "dask", N, seed=11, shard_size=7, scheduler=cluster,
                                   progress=events.append)
    serial = build_fabric_library(tmp_path / "serial", N, seed=11, shard_size=13, workers=0)
    assert on_dask["sha256"] == serial["sha256"]
    assert [f["digest"] for f in on_dask["fabrics"]] == [f["digest"] for f in serial["fabrics"]]
    assert on_dask["build"]["shards_built"] == 6 and serial["build"]["shards_built"] == 4
    # progress: a start, then one event per shard, the fabric count reaching N
    assert events[0]["event"] == "start" and events[0]["workers"] == 2 and events[0]["shards"] == 6
    assert [e["fabrics"] for e in events[1:]][-1] == N and len(events) == 7
    a, b = load_library(tmp_path / "dask"), load_library(tmp_path / "serial")
    for k in (0, 13, 27, 39):  # across shard boundaries of both plans
        for name, arr in a.arrays(k).items():
            np.testing.assert_array_equal(arr, b.arrays(k)[name])
    # every family, 8 fabrics each; another seed is another library
    assert {f: len(a.indices(f)) for f in LIBRARY_FAMILIES} == {f: N // 5 for f in LIBRARY_FAMILIES}
    other = build_fabric_library(tmp_path / "other", 5, seed=12, shard_size=5, workers=0)
    assert other["fabrics"][0]["digest"] != on_dask["fabrics"][0]["digest"]


def test_cli_builds_caches_and_refuses_bad_input(tmp_path, capsys):
    from kesbrdf.cli.main import main

    out = tmp_path / "lib"
    argv = ["simulate", "--fabric-library", "6", "-o", str(out), "--workers", "0", "--shard-size", "4",
            "--no-progress"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    sha = load_library(out).sha256
    assert f"sha256 {sha}" in err and "2 shard(s) built, 0 cached" in err
    assert main(argv) == 0
    assert "0 shard(s) built, 2 cached" in capsys.readouterr().err
    for bad, expected in (
        (["--fabric-library", "0"], "--fabric-library: expected an integer >= 1, got 0"),
        (["--fabric-library", "3", "--families", "ward,spongecake"], "--families: microflake/SGGX"),
        (["--fabric-library", "3", "--shard-size", "0"], "--shard-size: expected an integer >= 1, got 0"),
        (["--fabric-library", "3", "--library", "2"], "--fabric-library: expected it without --library"),
    ):
        assert main(["simulate", "-o", str(tmp_path / "x"), *bad]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and expected in lines[0], lines
    assert not (tmp_path / "x").exists()


def test_run_tasks_keeps_task_order_retries_and_then_raises():
    """The engine's generic task runner (serial path; the Dask path is the test above)."""
    from kesbrdf.batch.engine import run_tasks

    calls = {}

    def flaky(k, fail_times):
        calls[k] = calls.get(k, 0) + 1
        if calls[k] <= fail_times:
            raise RuntimeError(f"transient {k}")
        return k * k

    events = []
    assert run_tasks(flaky, [(3, 0), (1, 2), (2, 1)], workers=0, retries=2, progress=events.append) == [9, 1, 4]
    assert calls == {3: 1, 1: 3, 2: 2}
    assert [e["done"] for e in events if e["event"] == "task"] == [1, 2, 3]
    calls.clear()
    with pytest.raises(RuntimeError, match="transient 5"):
        run_tasks(flaky, [(5, 3)], workers=0, retries=2)
    assert calls == {5: 3}
