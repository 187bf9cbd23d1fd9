"""The batch under hostile input: FIFOs, tampered outputs, clashing ids, hanging steps.

Each test fails on the code before the fixes (checked by running them against it):
the FIFO made ``run_batch`` block forever (here: the run does not finish within
``FINISH_LIMIT_S``), an emptied output was "skipped", ``summary.csv`` as an id was
accepted and then broke the summary, a step that hung held the run, and nothing was
fsynced.  Tolerances: none; outputs are compared by sha256.
"""

from __future__ import annotations

import csv
import json
import os
import threading
import time
from pathlib import Path

import pytest

from batch_helpers import leftovers, manifests

#: Serial fit + validate of three small fabrics takes ~1-3 s, plus ~1 s to start the
#: step process; a run that blocks never finishes.  60 s separates the two on a loaded
#: 2-core machine without letting a regression hang the suite.
FINISH_LIMIT_S = 60.0
STEPS = ("fit", "validate")

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs POSIX FIFOs")


def _finishes(fn, *args, **kwargs):
    """``fn(...)`` in a daemon thread; its value, or a test failure if it blocks."""
    box = {}

    def run():
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - re-raised below
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(FINISH_LIMIT_S)
    assert not t.is_alive(), f"the batch did not finish within {FINISH_LIMIT_S} s (blocked?)"
    if "error" in box:
        raise box["error"]
    return box["value"]


def _hostile_catalog(library: Path, tmp: Path) -> Path:
    lib = library.parent
    os.mkfifo(tmp / "pipe.csv")  # a FIFO with no writer: opening it for reading blocks
    cat = tmp / "catalog.csv"
    # kind kes, asked for: hostile input, not the fit rule, is what these tests are about
    cat.write_text("id,input,kind\n"
                   f"good-a,{lib / 'fabric-001.csv'},kes\n"
                   f"good-b,{lib / 'fabric-002.csv'},kes\n"
                   "fifo,pipe.csv,kes\n"
                   f"Summary.CSV,{lib / 'fabric-001.csv'},kes\n")
    return cat


def _sha(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_fifo_tampered_outputs_and_clashing_id_finish_with_a_summary(library, tmp_path):
    from kesbrdf.batch import run_batch
    from kesbrdf.batch.summary import OUTPUT_FILES

    cat = _hostile_catalog(library, tmp_path)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    first = _finishes(run_batch, str(cat), out, steps=STEPS, workers=0)
    print(f"hostile batch finished in {time.perf_counter() - t0:.1f} s")
    rows = {r["id"]: r for r in csv.DictReader(open(out / "summary.csv"))}
    assert first.counts == {"done": 2, "failed": 2, "skipped": 0, "total": 4}
    assert rows["fifo"]["status"] == "failed" and rows["fifo"]["failed_step"] == "ingest"
    assert rows["fifo"]["error"] == f"{tmp_path / 'pipe.csv'}: expected a regular file, got a named pipe (FIFO)"
    names = ", ".join(OUTPUT_FILES.values())
    assert rows["Summary.CSV"]["failed_step"] == "catalog"
    assert rows["Summary.CSV"]["error"] == (f"{cat}:5: expected a fabric id other than the batch's own files in OUT "
                                            f"({names}; ignoring case), got 'Summary.CSV'")
    # every top-level output is a file written by the run, and nothing else is at the top
    assert sorted(p.name for p in out.iterdir() if p.is_file()) == sorted(OUTPUT_FILES.values())
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["good-a", "good-b"]

    # tamper: empty a model (what a power cut could leave), delete a validation, alter a measurement
    committed = {k: dict(v["outputs"]) for k, v in manifests(out).items()}
    model = out / "good-a" / "fit" / "model.kes.json"
    model.write_bytes(b"")
    (out / "good-b" / "validate" / "validation.json").unlink()
    meas = out / "good-b" / "ingest" / "measurement.csv"
    meas.write_bytes(meas.read_bytes().replace(b"1", b"2", 1))
    (out / "good-a" / "validate" / "manifest.json").unlink()
    os.mkfifo(out / "good-a" / "validate" / "manifest.json")  # reading it would block
    second = _finishes(run_batch, str(cat), out, steps=STEPS, workers=0)
    st = {r["id"]: r["steps"] for r in second.records}
    assert st["good-a"]["fit"]["status"] == "done" and st["good-a"]["fit"]["stale"].startswith(
        "model.kes.json: content differs from its manifest")
    assert st["good-a"]["ingest"]["status"] == "skipped"
    assert st["good-a"]["validate"]["status"] == "done"  # its manifest is a FIFO: not trusted, not read
    assert st["good-b"]["validate"]["status"] == "done"
    assert st["good-b"]["validate"]["stale"] == "validation.json: missing"
    assert st["good-b"]["ingest"]["status"] == "done"  # the altered measurement is rewritten from the input
    assert st["good-b"]["fit"]["status"] == "skipped"  # same bytes again: its input hash did not change
    assert second.counts == {"done": 2, "failed": 2, "skipped": 0, "total": 4}
    # recomputed byte for byte: every file again has the hash its manifest recorded
    assert {k: dict(v["outputs"]) for k, v in manifests(out).items()} == committed
    for (fid, step), outputs in committed.items():
        for name, digest in outputs.items():
            assert _sha(out / fid / step / name) == digest, (fid, step, name)
    third = _finishes(run_batch, str(cat), out, steps=STEPS, workers=0)
    assert third.counts == {"done": 0, "failed": 2, "skipped": 2, "total": 4}
    assert leftovers(out) == []


def _hang_hooks(tmp_path, fabric: str, seconds: float = 120.0) -> tuple[dict, Path]:
    record = tmp_path / "sleepers"
    return {"sleep": {"steps": ["fit"], "fabrics": [fabric], "seconds": seconds, "record": str(record)}}, record


def _assert_killed(record: Path, fabric: str) -> None:
    pids = [int(p.name.rsplit(".", 1)[1]) for p in record.glob(f"{fabric}.fit.*")]
    assert pids, "the hanging step never started"
    deadline = time.monotonic() + 5  # SIGKILL is immediate; reaping may lag a little
    for pid in pids:
        while time.monotonic() < deadline:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)
        else:
            pytest.fail(f"the step process {pid} of the timed-out step is still running")


#: Small enough for a fast test, large enough that a step of a good fabric (~20 ms of
#: work, plus ~1-2 s of imports on a step process's first call on a loaded machine: the
#: tests warm the step processes first) never reaches it.
TIMEOUT_S = 4.0


def test_a_hanging_step_is_killed_at_the_timeout_and_the_run_goes_on(library, tmp_path, monkeypatch):
    from kesbrdf.batch import read_catalog, run_batch
    from kesbrdf.batch.runner import TEST_HOOKS_ENV

    hooks, record = _hang_hooks(tmp_path, "fabric-002")
    hook_file = tmp_path / "hooks.json"
    hook_file.write_text(json.dumps(hooks))
    monkeypatch.setenv(TEST_HOOKS_ENV, str(hook_file))
    fabrics = read_catalog(library)[:3]
    # fabric-001 does not hang: this run does the imports in this thread's step process
    _finishes(run_batch, fabrics[:1], tmp_path / "warm", steps=STEPS, workers=0, write_summary=False)
    t0 = time.perf_counter()
    result = _finishes(run_batch, fabrics, tmp_path / "out", steps=STEPS, workers=0, task_timeout=TIMEOUT_S)
    seconds = time.perf_counter() - t0
    print(f"batch with one hanging step (timeout {TIMEOUT_S} s) finished in {seconds:.1f} s")
    rec = {r["id"]: r for r in result.records}
    assert rec["fabric-002"]["status"] == "failed" and rec["fabric-002"]["failed_step"] == "fit"
    assert rec["fabric-002"]["error"] == (f"fabric-002: step fit did not finish within {TIMEOUT_S:g} s "
                                          "(--task-timeout); its process was killed")
    assert rec["fabric-002"]["steps"]["validate"]["status"] == "blocked"
    assert rec["fabric-001"]["status"] == "ok" and rec["fabric-003"]["status"] == "ok"
    assert seconds < hooks["sleep"]["seconds"]  # did not wait for the sleep
    _assert_killed(record, "fabric-002")
    assert (tmp_path / "out" / "summary.csv").is_file() and leftovers(tmp_path / "out") == []


def test_a_hanging_step_on_a_dask_worker_is_killed_and_the_worker_goes_on(cluster, library, hooks, tmp_path):
    from kesbrdf.batch import read_catalog, run_batch

    doc, record = _hang_hooks(tmp_path, "fabric-001")
    fabrics = read_catalog(library)[:3]
    _finishes(run_batch, fabrics, tmp_path / "warm", steps=("fit",), scheduler=cluster, write_summary=False)
    hooks(doc)
    result = _finishes(run_batch, fabrics, tmp_path / "out", steps=("fit",), scheduler=cluster,
                       task_timeout=TIMEOUT_S)
    rec = {r["id"]: r for r in result.records}
    assert rec["fabric-001"]["failed_step"] == "fit" and "did not finish within" in rec["fabric-001"]["error"]
    assert rec["fabric-002"]["status"] == "ok" and rec["fabric-003"]["status"] == "ok"
    _assert_killed(record, "fabric-001")
    assert len(cluster.scheduler_info()["workers"]) == 2  # the worker itself was not killed


def test_ids_are_checked_against_every_top_level_output_ignoring_case():
    from kesbrdf.batch.catalog import parse_catalog
    from kesbrdf.batch.summary import OUTPUT_FILES
    from kesbrdf.errors import FormatError

    names = list(OUTPUT_FILES.values())
    text = "id,input\nok,a.csv\n" + "".join(f"{n.upper()},a.csv\n" for n in names)
    fabs = parse_catalog(text, "cat.csv")
    assert fabs[0].error is None
    for k, (fab, name) in enumerate(zip(fabs[1:], names)):
        assert fab.error.startswith(f"cat.csv:{k + 3}: expected a fabric id other than the batch's own files")
        assert fab.error.endswith(f"got {name.upper()!r}") and "\n" not in fab.error
    with pytest.raises(FormatError, match=r"cat.csv:3: duplicate id 'a' \(first on line 2 as 'A'; ids differing"):
        parse_catalog("id,input\nA,a.csv\na,b.csv\n", "cat.csv")


def test_a_step_folder_is_fsynced_before_its_rename(tmp_path, monkeypatch):
    """A power cut after the rename must not leave a committed folder of empty files."""
    from kesbrdf.batch.store import Store

    store = Store(tmp_path / "out")
    scratch = store.scratch("fab", "fit")
    (scratch / "sub").mkdir()
    for name in ("model.kes.json", "sub/x.bin", "manifest.json"):
        (scratch / name).write_bytes(b"data")
    events = []
    real_fsync, real_rename = os.fsync, os.rename
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}"))),
                                                 real_fsync(fd))[1])
    monkeypatch.setattr(os, "rename", lambda a, b: (events.append(("rename", str(b))), real_rename(a, b))[1])
    if not os.path.exists("/proc/self/fd"):
        pytest.skip("needs /proc to name synced descriptors")
    assert store.commit(scratch, "fab", "fit", "manifest.json")
    k = events.index(("rename", store.path("fab", "fit")))
    synced_before = {e[1] for e in events[:k] if e[0] == "fsync"}
    assert {str(scratch / n) for n in ("model.kes.json", "sub/x.bin", "manifest.json", "sub")} | {str(scratch)} \
        <= synced_before
    assert ("fsync", store.path("fab")) in events[k + 1:]  # the rename itself


def test_cli_task_timeout_flag(library, tmp_path, capsys):
    from kesbrdf.cli.main import main

    cat = _hostile_catalog(library, tmp_path)
    assert main(["batch", str(cat), "-o", str(tmp_path / "x"), "--task-timeout", "-1"]) == 2
    assert "--task-timeout: expected seconds >= 0 (0: no limit), got -1.0" in capsys.readouterr().err
    # a catalogue that is a FIFO: one line, exit 2, no hang
    assert _finishes(main, ["batch", str(tmp_path / "pipe.csv"), "-o", str(tmp_path / "y")]) == 2
    assert f"{tmp_path / 'pipe.csv'}: expected a regular file, got a named pipe (FIFO)" in capsys.readouterr().err
    code = _finishes(main, ["batch", str(cat), "-o", str(tmp_path / "cli"), "--workers", "0", "--steps", "fit",
                            "--task-timeout", "30", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0 and "2 done, 0 skipped (up to date), 2 failed of 4" in err
    assert f"failed fifo (ingest): {tmp_path / 'pipe.csv'}: expected a regular file, got a named pipe (FIFO)" in err
