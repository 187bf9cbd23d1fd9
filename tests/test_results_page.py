"""docs/results.md is generated from benchmarks/results.json and must match it.

The docs describe methods; measured numbers live in ``benchmarks/results.json`` and are
shown on the one generated page ``docs/results.md`` (``benchmarks/results_page.py``).
A benchmark run that updates the JSON without regenerating the page fails here.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("results_page", ROOT / "benchmarks" / "results_page.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_results_page_is_generated_from_committed_results():
    rp = _module()
    expected = rp.page(json.loads((ROOT / "benchmarks" / "results.json").read_text(encoding="utf-8")))
    committed = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    assert committed == expected, "docs/results.md is stale: run python benchmarks/results_page.py"


def test_page_shows_every_benchmark_and_its_values():
    rp = _module()
    results = {
        "kesbrdf_version": "9.9",
        "machine": {"cpus": 2, "python": "3.11"},
        "benchmarks": {
            "toy": {"speed_per_s": 1234567.0, "rows": 3,
                    "per_fabric": {"felt": {"rmse": 0.012345, "kind": "kes"}, "velvet": {"rmse": 0.5, "kind": "fibre-prior"}}},
        },
        "provenance": {"toy": "a test run"},
    }
    text = rp.page(results)
    assert "## toy" in text and "Run: a test run" in text
    # four significant digits, one row per record, a column per record field
    assert "| speed_per_s | 1.235e+06 |" in text
    assert "| | rmse | kind |" in text
    assert "| felt | 0.01235 | kes |" in text and "| velvet | 0.5 | fibre-prior |" in text
    # a changed value changes the page: the sync test above can fail
    results["benchmarks"]["toy"]["rows"] = 4
    assert rp.page(results) != text
