"""The test suite itself: no skips of the project's own modules, render tests visible when skipped."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def test_no_importorskip_of_the_projects_own_modules():
    pattern = re.compile(r"importorskip\(\s*['\"]kesbrdf")
    offenders = [
        str(p.relative_to(ROOT)) for p in TESTS.rglob("*.py") if pattern.search(p.read_text(encoding="utf-8"))
    ]
    assert offenders == [], "core modules must import; an ImportError there is a failure, not a skip"


HIDE_RENDERER = """
import sys
sys.modules["mitsuba"] = None  # as if kesbrdf[render] were not installed
sys.modules["drjit"] = None
import pytest
sys.exit(pytest.main(["-q", "-rs", "-p", "no:cacheprovider", "tests/render"]))
"""


def test_render_tests_are_reported_as_skipped_without_mitsuba():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(
        [sys.executable, "-c", HIDE_RENDERER], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    modules = sorted((TESTS / "render").glob("test_*.py"))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert f"{len(modules)} skipped" in proc.stdout, proc.stdout[-2000:]
    assert "render tests need mitsuba and drjit" in proc.stdout
