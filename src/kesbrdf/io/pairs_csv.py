"""Reader of direction-pair CSV files (``kesbrdf eval --pairs``, ``docs/formats.md``).

A header row naming at least ``theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg`` (in any
order; other columns are ignored), then one pair of directions per row, in degrees:
polar angles in [0, 90], azimuths in [-360, 360].  Blank lines and lines starting
with ``#`` are skipped.  The text rules of :mod:`kesbrdf.io.text` apply (UTF-8 with
or without BOM, any line ending, bounded line length, finite numbers).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kesbrdf.errors import FormatError, where
from kesbrdf.io.files import read_regular
from kesbrdf.io.text import csv_fields, decode_text, parse_number, split_lines

__all__ = ["PAIR_COLUMNS", "read_pairs", "parse_pairs"]

#: Columns every pairs file must have (degrees).
PAIR_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")

#: Accepted range of each column, degrees.
_RANGES = {
    "theta_i_deg": (0.0, 90.0),
    "theta_r_deg": (0.0, 90.0),
    "phi_i_deg": (-360.0, 360.0),
    "phi_r_deg": (-360.0, 360.0),
}


def read_pairs(path) -> np.ndarray:
    """Read a pairs CSV; return the pairs as a float array (N, 4) in :data:`PAIR_COLUMNS` order, degrees.

    Raises
    ------
    FormatError
        Undecodable text, a missing column, a non-numeric or out-of-range angle,
        a short row; the message names ``file:line``.
    """
    path = Path(path)
    return parse_pairs(decode_text(read_regular(path), path), path)


def parse_pairs(text: str, source: object = "<string>") -> np.ndarray:
    """Parse pairs CSV ``text`` (see :func:`read_pairs`); ``source`` names it in errors.

    >>> parse_pairs("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg\\r\\n30,0,30,180\\r\\n").tolist()
    [[30.0, 0.0, 30.0, 180.0]]
    """
    header = None
    idx: list[int] = []
    rows: list[list[float]] = []
    for lineno, line in split_lines(text, source):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = csv_fields(line, source, lineno)
        if header is None:
            header = [h.strip() for h in fields]
            missing = [c for c in PAIR_COLUMNS if c not in header]
            if missing:
                raise FormatError(
                    f"{where(source, lineno)}missing column(s) {', '.join(missing)}; expected {','.join(PAIR_COLUMNS)}"
                )
            duplicated = [c for c in PAIR_COLUMNS if header.count(c) > 1]
            if duplicated:
                raise FormatError(f"{where(source, lineno)}column {duplicated[0]!r} appears twice")
            idx = [header.index(c) for c in PAIR_COLUMNS]
            continue
        row = []
        for name, k in zip(PAIR_COLUMNS, idx):
            if k >= len(fields):
                raise FormatError(
                    f"{where(source, lineno)}column {name}: expected a number, got nothing "
                    f"({len(fields)} field(s) on the line, {len(header)} in the header)"
                )
            value = parse_number(fields[k], name, source, lineno)
            lo, hi = _RANGES[name]
            if not lo <= value <= hi:
                raise FormatError(f"{where(source, lineno)}column {name}: expected degrees in [{lo:g}, {hi:g}], got {value:g}")
            row.append(value)
        rows.append(row)
    if header is None:
        raise FormatError(f"{where(source)}expected a header {','.join(PAIR_COLUMNS)}, got an empty file")
    return np.array(rows, float).reshape(-1, 4)
