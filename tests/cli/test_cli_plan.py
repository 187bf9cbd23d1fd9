"""``kesbrdf plan`` through the real CLI: bad input gives one line and exit 2."""

from __future__ import annotations

import subprocess
import sys


def _run(*args, cwd):
    return subprocess.run([sys.executable, "-m", "kesbrdf.cli.main", *args], capture_output=True, text=True, cwd=cwd)


def test_plan_rejects_bad_output_suffix_before_work(tmp_path):
    r = _run("plan", "--reference", "ward", "-o", str(tmp_path / "plan.txt"), cwd=tmp_path)
    assert r.returncode == 2
    assert "expected a file ending in .json" in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "plan.txt").exists()


def test_plan_needs_a_truth(tmp_path):
    r = _run("plan", "-o", str(tmp_path / "plan.json"), cwd=tmp_path)
    assert r.returncode == 2
    assert "expected --reference" in r.stderr


def test_plan_unknown_reference_lists_names(tmp_path):
    r = _run("plan", "--reference", "banana", "-o", str(tmp_path / "plan.json"), cwd=tmp_path)
    assert r.returncode == 2
    assert "banana" in r.stderr and "ward" in r.stderr
