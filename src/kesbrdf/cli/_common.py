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


def check_output(path, suffixes: tuple[str, ...] = (), flag: str = "-o", folder: bool = False):
    """Check an output path before any long work starts; return it as a :class:`~pathlib.Path`.

    The one rule of every command's output (``-o``, ``--json``, ...; docs/decisions.md,
    "Outputs and write errors"): kesbrdf creates the output and the one folder that holds
    it, never the folders above: ``-o out/m.kes.json`` creates ``out`` when it is
    missing, ``-o results/2026/m.kes.json`` with no ``results`` is an error naming
    ``results`` (a mistyped path must not grow a tree silently).

    For a file output (``folder=False``) the suffix must be one of ``suffixes``
    (case-insensitive; ``()`` accepts any) and the path must not be an existing folder;
    a folder output (``folder=True``: ``demo -o``, ``drape -o``) must not be an
    existing file.  Every name must fit the file system's limit, and the nearest
    existing folder must be a writable folder.

    Raises
    ------
    KesbrdfError
        One line naming ``flag``, the path and what is wrong.
    """
    import os
    from pathlib import Path

    from kesbrdf._atomic import name_max

    out = Path(path)
    holder = out.parent
    limit = name_max(holder)
    for part in out.parts:
        n = len(os.fsencode(part))
        if n > limit:
            raise KesbrdfError(f"{flag} {out}: file name too long ({n} bytes in {part[:24]}..., "
                               f"at most {limit} on this file system)")
    if not folder:
        if suffixes and not out.name.lower().endswith(tuple(s.lower() for s in suffixes)):
            raise KesbrdfError(
                f"{flag} {out}: expected a file ending in {', '.join(suffixes)}, got {out.suffix or 'no suffix'!r}"
            )
        if out.is_dir():
            raise KesbrdfError(f"{flag} {out}: expected a file name, got an existing folder")
    elif out.exists() and not out.is_dir():
        raise KesbrdfError(f"{flag} {out}: expected a folder, got an existing file")
    parent = holder
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise KesbrdfError(f"{flag} {out}: expected a folder to write into, but {parent} is a file")
    if parent not in (holder, holder.parent):
        missing = next(p for p in reversed(holder.parents) if not p.exists())
        raise KesbrdfError(f"{flag} {out}: folder {missing} does not exist (kesbrdf creates only the folder "
                           f"{holder} that holds the output; create the folders above it first)")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise KesbrdfError(f"{flag} {out}: folder {parent} is not writable")
    return out
