"""Small helpers shared by CLI commands (terminal output only lives in the CLI)."""

from __future__ import annotations

import sys

from kesbrdf.errors import KesbrdfError
# The one registry of reference BRDFs lives in the library; the CLI re-exports it.
from kesbrdf.references.registry import REFERENCES, make_reference  # noqa: F401 (re-exported)


def stderr(text: str) -> None:
    print(text, file=sys.stderr)


def print_metrics(result: dict, title: str = "") -> None:
    """Print a per-channel metrics table (rich if available)."""
    rows = result["metrics"] if "metrics" in result else result
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:  # pragma: no cover - rich is in the cli extra
        for ch, m in rows.items():
            print(ch, " ".join(f"{k}={v:.4g}" for k, v in m.items()))
        return
    table = Table(title=title or None)
    for col in ("channel", "n", "rmse [1/sr]", "nrmse", "log_rmse", "max_abs [1/sr]"):
        table.add_column(col, justify="right")
    for ch, m in rows.items():
        table.add_row(ch, str(m["n"]), f"{m['rmse']:.4g}", f"{m['nrmse']:.4g}", f"{m['log_rmse']:.4g}", f"{m['max_abs']:.4g}")
    Console().print(table)


def check_output(path, suffixes: tuple[str, ...], flag: str = "-o"):
    """Check an output path before any long work starts; return it as a :class:`~pathlib.Path`.

    The suffix must be one of ``suffixes`` (case-insensitive; ``()`` accepts any), the
    path must not be an existing folder, and its nearest existing parent must be a
    writable folder (missing folders are created when the output is written).

    Raises
    ------
    KesbrdfError
        One line naming ``flag`` and the path.
    """
    import os
    from pathlib import Path

    out = Path(path)
    if suffixes and not out.name.lower().endswith(tuple(s.lower() for s in suffixes)):
        raise KesbrdfError(
            f"{flag} {out}: expected a file ending in {', '.join(suffixes)}, got {out.suffix or 'no suffix'!r}"
        )
    if out.is_dir():
        raise KesbrdfError(f"{flag} {out}: expected a file name, got an existing folder")
    parent = out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise KesbrdfError(f"{flag} {out}: expected a folder to write into, but {parent} is a file")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise KesbrdfError(f"{flag} {out}: folder {parent} is not writable")
    return out

