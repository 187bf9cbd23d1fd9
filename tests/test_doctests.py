"""Every docstring example of the package runs (the doctests are part of ``make test``).

Modules whose optional dependency is missing (matplotlib, mitsuba, newton, ...) are
reported as skipped with the missing module's name; any other import error fails.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import kesbrdf

#: Top-level packages of optional extras (pyproject.toml); a module that cannot import
#: one of them is skipped, not failed.
OPTIONAL = {
    "matplotlib", "mitsuba", "drjit", "newton", "warp", "imageio", "tifffile", "OpenEXR", "PIL",
    "rich", "dask", "distributed", "fsspec", "pyarrow", "tqdm", "MaterialX", "pxr", "pygltflib",
    "flip_evaluator", "pyoidn", "scipy", "imageio_ffmpeg", "uvicorn", "h11",
}


def _modules() -> list[str]:
    names = [kesbrdf.__name__]
    for info in pkgutil.walk_packages(kesbrdf.__path__, prefix="kesbrdf."):
        names.append(info.name)
    return sorted(names)


@pytest.mark.parametrize("name", _modules())
def test_docstring_examples_run(name):
    try:
        module = importlib.import_module(name)
    except ImportError as exc:
        missing = (getattr(exc, "name", None) or "").split(".")[0]
        if missing in OPTIONAL:
            pytest.skip(f"{name} needs the optional {missing}")
        raise
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    for test in finder.find(module, name):
        if test.examples and test.filename and test.filename.endswith(".py"):
            runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)[:4000]
