"""The batch on a real LocalCluster: faults, restarts, equality with a serial run.

Tolerances: none.  Every worker runs one thread with single-threaded BLAS, so a fabric's
numbers do not depend on where it ran; the tests demand bit-identical output files
(equal sha256 of every file every step wrote) between the serial and the Dask runs.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from batch_helpers import N_BROKEN, N_GOOD, leftovers, manifests

CORE = ("fit", "validate", "export")
#: The export step with the cheapest format (BRDF Explorer: a baked table, ~0.1 s); every
#: format's own file is tested in tests/export, and the analytic fits take 20-50 s each.
FAST = {"export": {"formats": ["brdf-explorer"]}}


def _outputs(out: Path) -> dict:
    """{(fabric, step): {file: sha256}} of every committed step."""
    return {k: v["outputs"] for k, v in manifests(out).items()}


@pytest.fixture(scope="module")
def serial(library, tmp_path_factory):
    """The reference: the same steps serially in this process (workers=0)."""
    from kesbrdf.batch import run_batch

    out = tmp_path_factory.mktemp("serial")
    result = run_batch(library, out, steps=CORE, workers=0, settings=FAST)
    return out, result


def test_serial_run_reports_broken_fabrics_and_leaves_no_partial_output(serial):
    out, result = serial
    assert result.counts == {"done": N_GOOD, "failed": N_BROKEN, "skipped": 0, "total": N_GOOD + N_BROKEN}
    rows = {r["id"]: r for r in csv.DictReader(open(out / "summary.csv"))}
    assert len(rows) == N_GOOD + N_BROKEN
    bad = rows["broken-1-bad-value"]
    # the reader's one-line message, with file:line, and the step it failed in
    assert bad["status"] == "failed" and bad["failed_step"] == "ingest"
    assert "broken-1-bad-value.csv:" in bad["error"] and "expected a number, got 'n/a'" in bad["error"]
    assert "\n" not in bad["error"]
    miss = rows["broken-2-missing-orientations"]
    assert miss["failed_step"] == "fit" and "missing 45, 90" in miss["error"]
    gone = rows["broken-3-missing-file"]
    assert gone["failed_step"] == "ingest" and "No such file or directory" in gone["error"]
    # no folder of a failed step, no scratch folder, no step folder without its manifest
    assert not (out / "broken-2-missing-orientations" / "fit").exists()
    assert (out / "broken-2-missing-orientations" / "ingest" / "manifest.json").is_file()
    assert not (out / "broken-1-bad-value" / "ingest").exists()
    assert leftovers(out) == []
    for fid, r in rows.items():
        if fid.startswith("fabric-"):
            assert r["status"] == "ok" and r["error"] == ""
            assert r["kind"] == "kes" and int(r["n_samples"]) == 116
            # the references are smooth: a 4-orientation KES model predicts held-out
            # orientations within 35 % relative RMSE (Ashikhmin-Shirley's sharp lobes are the worst)
            assert 0 < float(r["ref_nrmse"]) < 0.35
            assert float(r["fit_nrmse"]) < 1e-12  # the table interpolates its inputs exactly
            assert (out / r["model"]).is_file()
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet").to_pydict()
    assert table["id"] == list(rows)
    assert table["status"].count("failed") == N_BROKEN
    assert (out / "index.html").read_text().count('class="t ') == N_GOOD + N_BROKEN


def test_rerun_skips_every_finished_step(serial, library, tmp_path):
    from kesbrdf.batch import run_batch

    out, _ = serial
    before = {k: (v["finished_unix"], (out / k[0] / k[1] / "manifest.json").stat().st_mtime_ns)
              for k, v in manifests(out).items()}
    again = run_batch(library, out, steps=CORE, workers=0, settings=FAST)
    assert again.counts["skipped"] == N_GOOD and again.counts["done"] == 0
    after = {k: (v["finished_unix"], (out / k[0] / k[1] / "manifest.json").stat().st_mtime_ns)
             for k, v in manifests(out).items()}
    assert after == before
    # a changed parameter recomputes exactly the steps that read it
    from kesbrdf.batch import read_catalog

    import shutil

    fabrics = read_catalog(library)
    fabrics[0].options["orientations"] = 3
    copy = shutil.copytree(out, tmp_path / "copy")
    third = run_batch(fabrics[:1], copy, steps=CORE, workers=0, write_summary=False, settings=FAST)
    st = third.records[0]["steps"]
    assert st["ingest"]["status"] == "skipped"
    assert st["fit"]["status"] == "done" and st["validate"]["status"] == "done"


def test_dask_run_equals_serial_bit_for_bit_with_a_worker_killed(cluster, serial, library, hooks, tmp_path):
    """Kill the worker that is busy mid-run: the batch still completes, identically."""
    from kesbrdf.batch import run_batch

    hooks({"sleep": {"steps": ["fit"], "seconds": 0.4}})
    killed = []

    def kill_busy_worker(ev):
        if ev["event"] != "fabric" or killed:
            return
        busy = [w for w, keys in cluster.processing().items() if keys]
        if busy:
            pid = cluster.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    out = tmp_path / "dask"
    result = run_batch(library, out, steps=CORE, scheduler=cluster, retries=2, progress=kill_busy_worker, settings=FAST)
    assert killed, "no worker was busy to kill"
    # a fabric whose finished result died with the worker is rerun and then finds every
    # step committed: it counts as skipped, not recomputed
    assert result.counts["done"] + result.counts["skipped"] == N_GOOD and result.counts["failed"] == N_BROKEN
    ref_out, ref = serial
    assert _outputs(out) == _outputs(ref_out)
    assert [r["error"] for r in result.records] == [r["error"] for r in ref.records]
    assert leftovers(out) == []
    cluster.wait_for_workers(2, timeout=30)  # the nanny restarted it for the next tests


def test_injected_transient_failure_is_retried(cluster, library, hooks, tmp_path):
    from kesbrdf.batch import run_batch

    record = tmp_path / "attempts"
    hooks({"fail_once": {"steps": ["fit"], "fabrics": ["fabric-001", "fabric-002"], "record": str(record)}})
    out = tmp_path / "retry"
    result = run_batch(library, out, steps=("fit",), scheduler=cluster, retries=1)
    assert result.counts["done"] == N_GOOD
    for fid in ("fabric-001", "fabric-002"):
        assert len(list(record.glob(f"{fid}.fit.*"))) == 2  # failed once, then succeeded
        assert (out / fid / "fit" / "manifest.json").is_file()
    # with no retries the same fault is reported as a (transient) failure of that fabric only
    record2 = tmp_path / "attempts2"
    hooks({"fail_once": {"steps": ["fit"], "fabrics": ["fabric-003"], "record": str(record2)}})
    out2 = tmp_path / "noretry"
    # (and through the scheduler's address, as `kesbrdf batch --scheduler tcp://...` does)
    result2 = run_batch(library, out2, steps=("fit",), scheduler=cluster.scheduler.address, retries=0)
    rec = {r["id"]: r for r in result2.records}["fabric-003"]
    assert rec["status"] == "failed" and "injected transient failure" in rec["error"] and rec["failed_step"] == "fit"
    assert rec["error"].startswith("transient failure persisted after 1 attempt(s): RuntimeError: ")
    assert result2.counts["done"] == N_GOOD - 1
    assert not (out2 / "fabric-003" / "fit").exists() and leftovers(out2) == []


def test_killed_driver_rerun_recomputes_nothing_finished(library, serial, tmp_path, hook_file):
    """SIGKILL `kesbrdf batch` mid-run; the rerun finishes and keeps every finished step."""
    from kesbrdf.batch import run_batch
    from kesbrdf.batch.runner import TEST_HOOKS_ENV

    hooks = tmp_path / "slow.json"
    hooks.write_text(json.dumps({"sleep": {"steps": ["validate"], "seconds": 0.7}}))
    out = tmp_path / "killed"
    env = {**os.environ, TEST_HOOKS_ENV: str(hooks), "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen([sys.executable, "-m", "kesbrdf.cli.main", "batch", str(library), "-o", str(out),
                             "--workers", "2", "--steps", ",".join(CORE), "--export-formats", "brdf-explorer", "--no-progress"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(list(out.glob("*/validate/manifest.json"))) < 2:
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)  # the driver and its workers, like a lost node
        proc.wait(10)
    finally:
        if proc.poll() is None:  # pragma: no cover
            os.killpg(proc.pid, signal.SIGKILL)
    finished = manifests(out)
    assert len([k for k in finished if k[1] == "validate"]) >= 2
    assert len([k for k in finished if k[1] == "validate"]) < N_GOOD, "the driver finished before it was killed"
    # committed steps are whole: every step folder has its manifest and all its files
    for (fid, step), doc in finished.items():
        for name, digest in doc["outputs"].items():
            assert (out / fid / step / name).is_file()
    stamps = {k: (out / k[0] / k[1] / "manifest.json").stat().st_mtime_ns for k in finished}
    hook_file.write_text("{}")
    result = run_batch(library, out, steps=CORE, workers=0, settings=FAST)
    assert result.counts["done"] + result.counts["skipped"] == N_GOOD
    for rec in result.records:
        for step, s in rec["steps"].items():
            if (rec["id"], step) in finished:
                assert s["status"] == "skipped", (rec["id"], step)
    assert {k: (out / k[0] / k[1] / "manifest.json").stat().st_mtime_ns for k in finished} == stamps
    assert _outputs(out) == _outputs(serial[0])
    assert leftovers(out) == []


def test_catalogue_errors_are_one_line_and_per_fabric(tmp_path):
    from kesbrdf.batch.catalog import parse_catalog
    from kesbrdf.errors import FormatError

    with pytest.raises(FormatError, match=r"cat.csv:1: unknown catalogue column 'orientation'"):
        parse_catalog("id,input,orientation\na,a.csv,3\n", "cat.csv")
    with pytest.raises(FormatError, match=r"cat.csv:3: duplicate id 'a' \(first on line 2\)"):
        parse_catalog("id,input\na,a.csv\na,b.csv\n", "cat.csv")
    with pytest.raises(FormatError, match=r"cat.csv:2: expected an id"):
        parse_catalog("id,input\n../x,a.csv\n", "cat.csv")
    fabs = parse_catalog("id,input,orientations,kind\na,a.csv,5,\nb,b.csv,3,kes\n", str(tmp_path / "cat.csv"))
    assert fabs[0].error == f"{tmp_path / 'cat.csv'}:2: column 'orientations': expected 3 or 4, got '5'"
    assert fabs[1].error is None and fabs[1].options == {"orientations": 3, "kind": "kes"}
    assert fabs[1].input == str(tmp_path / "b.csv")


def test_folder_catalogue_and_file_url_output(library, serial, tmp_path):
    from kesbrdf.batch import run_batch

    # ingest only: a folder catalogue has no kind column, so its fits are kesbrdf fit's
    # rule (~8 s CPU a fabric), where the catalogue asks for kes (conftest.py)
    result = run_batch(str(library.parent), f"file://{tmp_path}/viaurl", steps=("ingest",), workers=0)
    ids = [r["id"] for r in result.records]
    assert "fabric-003" in ids and "broken-1-bad-value" in ids and "catalog" not in ids
    got = _outputs(tmp_path / "viaurl")
    ref = _outputs(serial[0])
    # no reference options in a folder catalogue; ingest does not read them
    for key in (("fabric-001", "ingest"), ("fabric-003", "ingest")):
        assert got[key] == ref[key]


def test_cli_batch_serial_and_bad_catalogue(library, tmp_path, capsys):
    from kesbrdf.cli.main import main

    assert main(["batch", str(library), "-o", str(tmp_path / "cli"), "--workers", "0", "--steps", "fit",
                 "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"{N_GOOD} done, 0 skipped (up to date), {N_BROKEN} failed" in err
    assert "failed broken-1-bad-value (ingest):" in err
    bad = tmp_path / "bad.csv"
    bad.write_text("id,inptu\n")
    assert main(["batch", str(bad), "-o", str(tmp_path / "x")]) == 2
    assert "expected a column 'input'" in capsys.readouterr().err


@pytest.mark.render
def test_preview_on_render_workers(cluster, library, tmp_path):
    from kesbrdf.batch import run_batch
    from kesbrdf.batch.engine import render_available

    if not render_available():
        pytest.skip("needs Mitsuba + libLLVM")
    from kesbrdf.batch import read_catalog

    fab = read_catalog(library)[1:2]
    out = tmp_path / "preview"
    settings = {"preview": {"spp": 4, "resolution": [64, 48], "colourway_spp": 2, "colourway_resolution": [32, 24]}}
    result = run_batch(fab, out, steps=("preview",), scheduler=cluster, settings=settings)
    rec = result.records[0]
    assert rec["status"] == "ok", rec["error"]
    assert rec["steps"]["preview"]["status"] == "done"
    # Dr.Jit's pool capped at cores // workers (no oversubscription by 2 render workers)
    assert rec["steps"]["preview"]["result"]["drjit_threads"] == max(1, (os.cpu_count() or 1) // 2)
    from PIL import Image
    import numpy as np

    img = np.asarray(Image.open(out / fab[0].id / "preview" / "preview.png").convert("RGB"), float)
    assert img.shape == (48, 64, 3) and img.std() > 5  # a lit sphere, not a blank frame
    sheet = Image.open(out / fab[0].id / "preview" / "colourways.png")
    assert sheet.size == (3 * 32, 2 * 24)  # six colourway tiles, three per row
    assert "data:image/png;base64," in (out / "index.html").read_text()


def test_export_step_runs_every_listed_format(library, tmp_path, monkeypatch):
    """The export step iterates kesbrdf.export.FORMATS: none today, all after the merge."""
    import kesbrdf.export as ex
    from kesbrdf.batch import read_catalog, run_batch

    mod = tmp_path / "mods" / "kesbrdf_test_formats" / "fake.py"  # FORMATS values with a dot are full module names
    mod.parent.mkdir(parents=True)
    (mod.parent / "__init__.py").write_text("")
    mod.write_text(
        "import json\nfrom pathlib import Path\nfrom kesbrdf.export import ExportResult\nEXTENSIONS = ('.fake.json',)\n"
        "def export(model, out, **options):\n"
        "    Path(out).write_text(json.dumps({'channels': list(model.channels), 'shape': list(model.table.shape)}))\n"
        "    return ExportResult('fake', [out])\n"
    )
    monkeypatch.syspath_prepend(str(mod.parent.parent))
    fabrics = read_catalog(library)[:2]
    out = tmp_path / "out"
    monkeypatch.setattr(ex, "FORMATS", {})
    first = run_batch(fabrics, out, steps=("export",), workers=0)
    assert first.records[0]["steps"]["export"]["result"]["note"].startswith("no export formats installed")
    monkeypatch.setattr(ex, "FORMATS", {"fake": "kesbrdf_test_formats.fake", "broken": "kesbrdf_no_such_module"})
    second = run_batch(fabrics, out, steps=("export",), workers=0)
    st = second.records[0]["steps"]
    # a new format reruns export and nothing upstream
    assert st["fit"]["status"] == "skipped" and st["export"]["status"] == "done"
    doc = json.loads((out / fabrics[0].id / "export" / "fake" / "model.fake.json").read_text())
    assert doc["channels"] == ["R", "G", "B"] and len(doc["shape"]) == 3
    assert "broken" in st["export"]["result"]["failed"]  # a missing module fails alone
    row = next(csv.DictReader(open(out / "summary.csv")))
    assert row["exports"] == f"{fabrics[0].id}/export/fake/model.fake.json" and row["export_formats"] == "fake"
    assert row["export_errors"].startswith("broken: ")
    # choosing formats is a parameter of the step: only export reruns, with only that format
    third = run_batch(fabrics, out, steps=("export",), workers=0, settings={"export": {"formats": ["fake"]}})
    st = third.records[0]["steps"]
    assert st["fit"]["status"] == "skipped" and st["export"]["status"] == "done"
    assert st["export"]["result"]["formats"] == ["fake"] and st["export"]["result"]["failed"] == {}


def test_demo_batch_quick(tmp_path, cluster):
    from kesbrdf.batch.demo import DEMO_BROKEN, DEMO_FABRICS, run_demo_batch

    said = []
    result = run_demo_batch(tmp_path, quick=True, progress=said.append, scheduler=cluster)
    assert DEMO_FABRICS + DEMO_BROKEN >= 12 and DEMO_BROKEN == 2
    assert result.counts["failed"] == 2 and result.counts["done"] == DEMO_FABRICS
    assert (tmp_path / "results" / "index.html").is_file() and (tmp_path / "results" / "summary.parquet").is_file()
    assert said and "2 failed (as intended)" in said[0]


def test_local_cluster_is_loopback_spawned_and_sets_worker_environment(cluster):
    import dask

    info = cluster.scheduler_info()
    assert info["address"].startswith("tcp://127.0.0.1:")
    assert len(info["workers"]) == 2 and all(a.startswith("tcp://127.0.0.1:") for a in info["workers"])
    assert dask.config.get("distributed.worker.multiprocessing-method") == "spawn"
    env = cluster.run(lambda: {k: os.environ.get(k) for k in ("DRJIT_CACHE_DIR", "KESBRDF_DRJIT_THREADS",
                                                              "OMP_NUM_THREADS")})
    cores = os.cpu_count() or 1
    for e in env.values():
        assert e["DRJIT_CACHE_DIR"].startswith(tempfile.gettempdir())  # node-local, not $HOME or NFS
        assert e["KESBRDF_DRJIT_THREADS"] == str(max(1, cores // 2)) and e["OMP_NUM_THREADS"] == "1"
    # one thread per worker process, in separate processes
    assert {w["nthreads"] for w in info["workers"].values()} == {1}
    assert len(set(cluster.run(os.getpid).values())) == 2


def test_object_store_path_commits_manifest_last_and_skips_on_rerun(library, serial):
    """The no-rename commit used for s3:// and friends, on fsspec's in-process memory store."""
    import fsspec

    from kesbrdf.batch import run_batch

    url = "memory://kesbrdf-batch-test/out"
    fs = fsspec.filesystem("memory")
    if fs.exists("/kesbrdf-batch-test"):
        fs.rm("/kesbrdf-batch-test", recursive=True)
    first = run_batch(library, url, steps=("fit", "validate"), workers=0)
    assert first.counts["done"] == N_GOOD and first.counts["failed"] == N_BROKEN
    ref = _outputs(serial[0])
    for rec in first.records:
        for step in ("ingest", "fit", "validate"):
            if rec["status"] == "ok":
                doc = json.loads(fs.cat(f"/kesbrdf-batch-test/out/{rec['id']}/{step}/manifest.json"))
                assert doc["outputs"] == ref[(rec["id"], step)]  # same bytes as the local run
    assert fs.exists("/kesbrdf-batch-test/out/summary.parquet") and fs.exists("/kesbrdf-batch-test/out/index.html")
    again = run_batch(library, url, steps=("fit", "validate"), workers=0)
    assert again.counts["skipped"] == N_GOOD
    fs.rm("/kesbrdf-batch-test", recursive=True)


def test_catalogue_and_inputs_behind_an_fsspec_url(library, serial, tmp_path):
    """Inputs fetched through fsspec (memory:// here, s3:// in production), manifests with their frames."""
    import fsspec

    from kesbrdf.batch import run_batch

    fs = fsspec.filesystem("memory")
    if fs.exists("/kesbrdf-batch-lib"):
        fs.rm("/kesbrdf-batch-lib", recursive=True)
    fs.put(str(library.parent) + "/", "/kesbrdf-batch-lib/", recursive=True)
    result = run_batch("memory://kesbrdf-batch-lib/catalog.csv", tmp_path / "out", steps=("fit",), workers=0)
    assert result.counts["done"] == N_GOOD and result.counts["failed"] == N_BROKEN
    got, ref = _outputs(tmp_path / "out"), _outputs(serial[0])
    for fid in ("fabric-001", "fabric-003"):  # a measurement CSV and a camera manifest
        assert got[(fid, "ingest")] == ref[(fid, "ingest")]
    rec = {r["id"]: r for r in result.records}
    assert rec["fabric-003"]["steps"]["ingest"]["result"]["source"] == "manifest"
    assert "No such file or directory" in rec["broken-3-missing-file"]["error"]
    fs.rm("/kesbrdf-batch-lib", recursive=True)


def test_a_batch_fits_by_kesbrdf_fits_rule(tmp_path):
    """A fabric whose row sets no fit option gets the spec of a plain ``kesbrdf fit``
    (kind auto, no options, so the prior comparison runs): the fit is deterministic, so
    the same model.  Before 2026-12-03 the catalogue's defaults counted as options given
    and the batch skipped the comparison (fit reports with "comparison": null)."""
    from kesbrdf.batch.catalog import parse_catalog
    from kesbrdf.batch.runner import fabric_options
    from kesbrdf.batch.steps import step_params
    from kesbrdf.pipeline import FitSpec

    plain, asked, option = parse_catalog("id,input,reference,kind,fallback\na,a.csv,ward,,\nb,b.csv,ward,kes,\n"
                                         "c,c.csv,ward,,error\n", str(tmp_path / "cat.csv"))
    spec = FitSpec.from_row(step_params("fit", fabric_options(plain)))
    assert (spec.kind, dict(spec.options), spec.compare, spec.strict) == ("auto", {}, True, False)
    assert spec.to_json() == FitSpec().to_json()
    assert FitSpec.from_row(step_params("fit", fabric_options(asked))).to_json() == FitSpec("kes").to_json()
    # an option the row gives is passed on (and, as on the command line, turns the comparison off)
    assert dict(FitSpec.from_row(step_params("fit", fabric_options(option))).options) == {"fallback": "error"}
