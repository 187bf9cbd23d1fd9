"""Fit caches shared by the benchmark modules (not a benchmark itself).

A sweep that takes hours caches its rows on disk so that it can resume.  A row is only
valid for the code that fitted it, so the cache file's name carries a digest of the
package's source: after any change to ``src/kesbrdf`` a sweep starts a new cache
instead of serving rows of a superseded fit (keyed by fabric and fitter name alone, a
rerun of the library leave-one-family-out table after the dense rule changed would
have served the old rule's rows).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src" / "kesbrdf"


def source_digest(root: Path = SRC) -> str:
    """First 12 hex digits of the SHA-256 of every ``.py`` file under ``root`` (relative
    path and bytes, in sorted order)."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:12]


def code_cache(path: Path, code: str | None = None) -> Path:
    """``path`` with the source digest before its suffix: ``x.json`` → ``x_<code>.json``."""
    code = code or source_digest()
    return path.with_name(f"{path.stem}_{code}{path.suffix}")
