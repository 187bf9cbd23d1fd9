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


def test_scoreboard_gathers_the_families_and_skips_absent_sections():
    """The issue-20 scoreboard reads lofo_library, compare and error_budget into one per-family
    view (values at 4 significant digits, FLIP over its floor, the largest error band); with
    none of those sections the page has no scoreboard."""
    rp = _module()
    cell = {"orientations": 0.031, "hemispheres": 0.2054, "fit_cpu_s": 5.5, "errors": 0}
    benches = {
        "lofo_library": {"fitters": ["default"], "library": {"per_family": 6},
                         "families": {"ward": {"paper": {"default": cell},
                                               "dense": {"default": dict(cell, hemispheres=0.0766)}}},
                         "dense_over_paper_hemispheres": {"default": {"ward/a": 0.5, "ward/b": 1.2}}},
        "compare": {"satin-ward/paper": {"flip": 0.09, "noise_flip": 0.03, "rel_rmse": 0.1, "model_kind": "kes"}},
        "error_budget": {"families": {"ggx": {"hemispheres": 0.37, "albedo_ratio": {"0": 0.7, "45": 0.75},
                                              "bands": {"0-15": {"share": 0.01, "ratio": 1.0},
                                                        "60-90": {"share": 0.4, "ratio": 0.39}}}}},
    }
    lines = rp.scoreboard(benches)
    text = "\n".join(lines)
    assert "| ward | 0.031 / 0.2054 | 0.031 / 0.0766 | 1 of 2 | 5.5 / 5.5 |" in text
    assert "| satin-ward/paper | kes | 0.09 | 0.03 | 3 | 0.1 |" in text
    assert "| ggx | 0.37 | 60-90° | 40% | 0.39 | 0.7 / 0.75 |" in text
    assert "σ coverage" not in text  # calibrate_sigma absent: its table is left out
    assert rp.scoreboard({"toy": {"x": 1}}) == []
