"""Analytic fits are computed once per model: a cache keyed by the model's content.

glTF, GLB, MaterialX and USD exports of one model need the same fits (the glTF
material; OpenPBR, Standard Surface and the UsdPreviewSurface fallback), and each is
seconds of CPU.  :func:`kesbrdf.export.analytic_fit.fit_analytic` looks a fit up here
first:

- **in memory**, for the rest of the process (the demo, a batch worker, a notebook);
- **on disk**, one small JSON file per fit in :func:`cache_dir` (``analytic-fits/``
  under ``$KESBRDF_CACHE_DIR``, else ``$XDG_CACHE_HOME/kesbrdf``, else
  ``~/.cache/kesbrdf``), so separate ``kesbrdf export`` runs share it too.
  ``KESBRDF_CACHE_DIR=off`` turns the disk cache off.  :func:`cache_in` points it at
  another folder for a block of code: the pipeline's export step keeps the fits beside
  its outputs (``out/exports/analytic-fits/`` in the demo).

The key is the SHA-256 of the model's content (kind, channels, parameters and arrays:
:func:`model_digest`, the same for a model and the file it was saved to and loaded
from), the material, the fit and error grids, the solver budget and
:data:`FIT_VERSION` (bumped whenever the objective or a material model changes, so a
stale fit is never reused).  A target without content (a plain callable) is fitted
every time.  A damaged or foreign cache file is ignored and rewritten; files are
written atomically (:mod:`kesbrdf._atomic`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

import numpy as np

__all__ = ["FIT_VERSION", "CACHE_ENV", "cache_dir", "cache_in", "model_digest", "fit_key", "lookup", "store",
           "clear_memory"]

#: Part of every key: bump when the objective, the grids' meaning or a material changes.
FIT_VERSION = "image-space-4"
#: Environment variable naming the cache folder ("off" disables the disk cache).
CACHE_ENV = "KESBRDF_CACHE_DIR"
#: In-memory entries kept (least recently stored dropped first).
MEMORY_SIZE = 32

_MEMORY: dict[str, dict] = {}
#: Folder set by :func:`cache_in` (innermost first), before the environment's.
_OVERRIDE: list[Path] = []


@contextlib.contextmanager
def cache_in(folder):
    """Keep the on-disk fits in ``folder`` (itself, not a subfolder) inside this block."""
    _OVERRIDE.append(Path(folder))
    try:
        yield Path(folder)
    finally:
        _OVERRIDE.pop()


def cache_dir() -> Path | None:
    """The folder of the on-disk fit cache (:func:`cache_in`'s, else the environment's),
    or None when it is turned off."""
    if _OVERRIDE:
        return _OVERRIDE[-1]
    value = os.environ.get(CACHE_ENV)
    if value is not None and value.strip().lower() in ("off", "0", "none", "false"):
        return None
    if value:
        root = Path(value)
    elif os.environ.get("XDG_CACHE_HOME"):
        root = Path(os.environ["XDG_CACHE_HOME"]) / "kesbrdf"
    else:
        root = Path.home() / ".cache" / "kesbrdf"
    return root / "analytic-fits"


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def model_digest(target) -> str | None:
    """SHA-256 of a model's content (:func:`kesbrdf.pipeline.model_sha256`); None without one."""
    from kesbrdf.pipeline import model_sha256

    return model_sha256(target)


def fit_key(digest: str, material: str, options: dict) -> str:
    """The cache key of a fit of ``material`` to the model with ``digest``."""
    text = json.dumps([FIT_VERSION, digest, material, options], sort_keys=True, default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def lookup(key: str) -> tuple[dict | None, str]:
    """(fit record, "memory" | "disk") for ``key``, or (None, "miss")."""
    if key in _MEMORY:
        return _MEMORY[key], "memory"
    folder = cache_dir()
    if folder is None:
        return None, "miss"
    path = folder / f"{key}.json"
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None, "miss"
    if not isinstance(record, dict) or record.get("key") != key or not isinstance(record.get("fit"), dict):
        return None, "miss"
    _remember(key, record["fit"])
    return record["fit"], "disk"


def store(key: str, fit: dict) -> Path | None:
    """Keep ``fit`` (an ``AnalyticFit.as_dict()``) in memory and on disk; the file or None."""
    _remember(key, fit)
    folder = cache_dir()
    if folder is None:
        return None
    from kesbrdf._atomic import write_text

    try:
        folder.mkdir(parents=True, exist_ok=True)
        return write_text(folder / f"{key}.json", json.dumps({"key": key, "fit_version": FIT_VERSION, "fit": fit}, default=_json_default))
    except OSError:  # a read-only or full cache folder costs a refit next time, nothing else
        return None


def _remember(key: str, fit: dict) -> None:
    _MEMORY.pop(key, None)
    if len(_MEMORY) >= MEMORY_SIZE:
        _MEMORY.pop(next(iter(_MEMORY)))
    _MEMORY[key] = fit


def clear_memory() -> None:
    """Forget the in-memory fits (the disk cache stays)."""
    _MEMORY.clear()
