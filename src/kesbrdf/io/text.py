"""Text-file primitives shared by every kesbrdf reader (``docs/formats.md``, "Reading rules").

Each reader (measurement CSV, acquisition manifest, pairs CSV, CUReT tables) goes
through these few functions, so that all of them accept and refuse the same things
with the same one-line :class:`~kesbrdf.errors.FormatError`, naming ``file:line``:

* **Encoding**: UTF-8, with or without a byte-order mark (:func:`decode_text`).
  Other encodings (Latin-1, UTF-16) are refused with the line of the first bad byte.
* **Lines**: ``\\n``, ``\\r\\n`` and a lone ``\\r`` end a line (:func:`split_lines`);
  no other character does, so line numbers are the ones an editor shows.
* **Size**: a line may hold at most :data:`MAX_LINE_CHARS` characters (this bounds
  every field as well; the csv module's own limit never shows up as ``_csv.Error``).
* **Numbers**: :func:`parse_number` accepts what :class:`float` accepts and refuses
  NaN and infinities, and any value (huge exponents included) whose magnitude
  exceeds :data:`MAX_ABS_NUMBER`.
"""

from __future__ import annotations

import csv
import math
import re

from kesbrdf.errors import FormatError, where

__all__ = [
    "MAX_LINE_CHARS",
    "MAX_ABS_NUMBER",
    "decode_text",
    "split_lines",
    "csv_fields",
    "parse_number",
]

#: Longest line (characters) any reader accepts: a row of a few hundred spectral
#: bands written with ``repr`` is ~10 kB, so 1 MB leaves a wide margin while keeping
#: one line's memory bounded.
MAX_LINE_CHARS = 1 << 20

#: Largest magnitude accepted for a number in a file.  Every physical quantity of
#: the formats (angles in degrees, f_r in 1/sr, exposures in s) is far smaller; the
#: bound keeps products like ``value / cos θ`` or ``angle * 1000`` finite.
MAX_ABS_NUMBER = 1e100

_LINE_BREAK = re.compile(r"\r\n|\r|\n")


def decode_text(data: bytes, source: object) -> str:
    """Decode a file's bytes as UTF-8 (an initial byte-order mark is dropped).

    Raises
    ------
    FormatError
        Undecodable bytes (another encoding, binary data), naming the line of the
        first bad byte; or NUL characters, which no text format of kesbrdf contains.

    Examples
    --------
    >>> decode_text(b"\\xef\\xbb\\xbfpsi_deg\\n", "a.csv")
    'psi_deg\\n'
    >>> decode_text(b"a\\nb\\xe9\\n", "a.csv")
    Traceback (most recent call last):
    ...
    kesbrdf.errors.FormatError: a.csv:2: expected UTF-8 text, got the byte 0xe9 (another encoding such as Latin-1? save the file as UTF-8)
    """
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        bad = data[exc.start : exc.start + 1].hex()
        raise FormatError(
            f"{where(source, line)}expected UTF-8 text, got the byte 0x{bad} "
            "(another encoding such as Latin-1? save the file as UTF-8)"
        ) from None
    nul = text.find("\x00")
    if nul >= 0:
        line = text.count("\n", 0, nul) + 1
        raise FormatError(f"{where(source, line)}expected text, got a NUL character (binary data?)")
    return text


def split_lines(text: str, source: object):
    """Yield ``(line number, line)`` for every line of ``text`` (1-based numbers).

    Raises
    ------
    FormatError
        A line longer than :data:`MAX_LINE_CHARS` characters.
    """
    for lineno, line in enumerate(_LINE_BREAK.split(text), start=1):
        if len(line) > MAX_LINE_CHARS:
            raise FormatError(
                f"{where(source, lineno)}expected lines of at most {MAX_LINE_CHARS} characters, "
                f"got {len(line)}"
            )
        yield lineno, line


def csv_fields(line: str, source: object, lineno: int) -> list[str]:
    """The comma-separated fields of one line (csv quoting rules; fields not stripped).

    Raises
    ------
    FormatError
        A quoting error (e.g. a quote that is never closed on the line).

    Examples
    --------
    >>> csv_fields('1,"4,4,28,28"', "f.csv", 3)
    ['1', '4,4,28,28']
    """
    if len(line) > MAX_LINE_CHARS:
        raise FormatError(
            f"{where(source, lineno)}expected lines of at most {MAX_LINE_CHARS} characters, got {len(line)}"
        )
    limit = csv.field_size_limit()
    try:
        if limit < MAX_LINE_CHARS + 1:
            csv.field_size_limit(MAX_LINE_CHARS + 1)
        return next(csv.reader([line], strict=False), [])
    except csv.Error as exc:
        raise FormatError(f"{where(source, lineno)}expected comma-separated fields, got a malformed line ({exc})") from None


def parse_number(text: str, column: str, source: object, lineno: int | None, empty: float | None = None) -> float:
    """A finite float from a field; ``empty`` (if given) is returned for an empty field.

    Raises
    ------
    FormatError
        Not a number, NaN, infinite, or larger in magnitude than :data:`MAX_ABS_NUMBER`.

    Examples
    --------
    >>> parse_number(" 87.5 ", "theta_i_deg", "m.csv", 4)
    87.5
    >>> parse_number("nan", "value", "m.csv", 4)
    Traceback (most recent call last):
    ...
    kesbrdf.errors.FormatError: m.csv:4: column value: expected a finite number, got 'nan'
    """
    cell = text.strip()
    if cell == "" and empty is not None:
        return empty
    try:
        value = float(cell)
    except (ValueError, OverflowError):
        raise FormatError(f"{where(source, lineno)}column {column}: expected a number, got {_show(cell)}") from None
    if not math.isfinite(value):
        raise FormatError(f"{where(source, lineno)}column {column}: expected a finite number, got {_show(cell)}")
    if abs(value) > MAX_ABS_NUMBER:
        raise FormatError(
            f"{where(source, lineno)}column {column}: expected a number of magnitude <= {MAX_ABS_NUMBER:g}, "
            f"got {_show(cell)}"
        )
    return value


def _show(cell: str) -> str:
    """``repr`` of a field, shortened so that one huge field does not make a huge message."""
    shown = repr(cell)
    return shown if len(shown) <= 60 else shown[:57] + "..."
