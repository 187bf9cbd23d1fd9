"""Fixtures for the renderer tests: small model files fitted from reference BRDFs.

Every test here needs Mitsuba 3 with an LLVM ≥ 17 backend (docs/architecture.md, "Tools it runs on").  When ``mitsuba``
or ``drjit`` is not installed, each test module of this folder is reported as SKIPPED
(one entry per module, with the reason), not silently left out: the modules are not
imported, since they need the renderer at import time.
"""

import importlib.util

import numpy as np
import pytest


def _installed(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):  # e.g. sys.modules[name] = None
        return False


MISSING = [name for name in ("mitsuba", "drjit") if not _installed(name)]
SKIP_REASON = f"render tests need {' and '.join(MISSING)} (install kesbrdf[render])"


class _SkippedModule(pytest.File):
    """Stands in for a test module that cannot be imported: one item, skipped with the reason."""

    def collect(self):
        yield _SkippedItem.from_parent(self, name=self.path.stem)


class _SkippedItem(pytest.Item):
    def runtest(self):
        pytest.skip(SKIP_REASON)

    def reportinfo(self):
        return self.path, None, f"{self.path.name} (skipped: {SKIP_REASON})"


def pytest_pycollect_makemodule(module_path, parent):
    if MISSING:
        return _SkippedModule.from_parent(parent, path=module_path)
    return None


@pytest.fixture(scope="session")
def rolled_model_file():
    """Factory: save a model with its table turned in φ (see :func:`_rolled_model_file`)."""
    return _rolled_model_file


def _rolled_model_file(model, path, quarter_turns: int = 1):
    """Save ``model`` with its table turned by quarter_turns·90° in φ: q'(φ) = q(φ − k·90°)."""
    import copy

    m = copy.copy(model)
    n_phi = model.table.shape[0]
    assert n_phi % 4 == 0
    m.table = np.roll(model.table, quarter_turns * n_phi // 4, axis=0)
    m.save(path)
    return path
