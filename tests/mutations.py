"""Hypothesis strategies that mutate valid input files (shared by the reader fuzz tests).

:func:`mutated` turns one valid file (bytes) into a broken variant by applying one to
a few mutations.  Text mutations work on lines and comma/space-separated fields (the
formats of docs/formats.md); byte mutations work on anything, images included:

* byte level: truncation, byte flips, inserted/deleted bytes;
* encodings: UTF-8 BOM, Latin-1 bytes, UTF-16, NUL bytes;
* line endings: CRLF, lone CR, missing final newline;
* lines: deleted, duplicated, swapped, one very long line (past the csv module's
  131,072-character field limit);
* fields: emptied, replaced by huge numbers (1e306, 1e999, 400-digit integers),
  NaN/inf text, unicode digits and symbols, quotes, random text; columns added or
  dropped.

:func:`examples` gives the number of examples a fuzz test runs: the suite's small
count, or the active profile's under ``HYPOTHESIS_PROFILE=fuzz`` (``make fuzz``,
profiles registered in ``tests/conftest.py``).
"""

from __future__ import annotations

import os
import re

from hypothesis import settings
from hypothesis import strategies as st

__all__ = ["examples", "mutated", "FIELD_VALUES", "TEXT_OPS", "BYTE_OPS"]

#: Characters past the csv module's default field limit (131,072).
LONG_FIELD = 140_000


def examples(normal: int) -> int:
    """``normal`` in the test suite; the profile's ``max_examples`` under ``HYPOTHESIS_PROFILE=fuzz``."""
    if os.environ.get("HYPOTHESIS_PROFILE") == "fuzz":
        return settings().max_examples
    return normal


#: Field values that broke (or could break) readers: non-finite and huge numbers,
#: number-like unicode, quoting, separators, control characters.
FIELD_VALUES = st.one_of(
    st.sampled_from(
        [
            "", " ", "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e999",
            "1e306", "-1e306", "1e-320", "5e-324", "-0", "0", "90", "90.0000001", "89.9999999",
            "180", "360", "-360", "361", "1e100", "1e101", "9" * 400, "9" * 5000, "0x10", "1_000",
            "١٢", "½", "Ⅻ", "\u2028", "\u00a0", '"', '"a,b"', "a,b", ";", "é", "\x00", "\x0b",
            "\ufeff", "#", "# quantity: radiance_ratio", "TRUE", "[1,2]", "{}", "null",
            "2**32", "4294967296", "-1", "1e6", "R", "value", "psi_deg",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.text(max_size=12),
)


def _split_lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


def _join(lines: list[bytes]) -> bytes:
    return b"\n".join(lines)


def _pick_line(draw, lines):
    return draw(st.integers(0, max(len(lines) - 1, 0)))


def _fields(line: bytes) -> tuple[list[bytes], bytes]:
    sep = b"," if b"," in line else b" "
    return line.split(sep), sep


# -- byte mutations ---------------------------------------------------------------
def _truncate(draw, data):
    return data[: draw(st.integers(0, len(data)))]


def _flip(draw, data):
    if not data:
        return data
    i = draw(st.integers(0, len(data) - 1))
    return data[:i] + bytes([draw(st.integers(0, 255))]) + data[i + 1 :]


def _insert_bytes(draw, data):
    i = draw(st.integers(0, len(data)))
    return data[:i] + draw(st.binary(min_size=1, max_size=8)) + data[i:]


def _delete_span(draw, data):
    i = draw(st.integers(0, len(data)))
    return data[:i] + data[i + draw(st.integers(1, 64)) :]


BYTE_OPS = (_truncate, _flip, _insert_bytes, _delete_span)


# -- text mutations ---------------------------------------------------------------
def _replace_field(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    fields, sep = _fields(lines[k])
    j = draw(st.integers(0, len(fields) - 1))
    fields[j] = draw(FIELD_VALUES).encode("utf-8", "surrogatepass")
    lines[k] = sep.join(fields)
    return _join(lines)


def _empty_field(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    fields, sep = _fields(lines[k])
    fields[draw(st.integers(0, len(fields) - 1))] = b""
    lines[k] = sep.join(fields)
    return _join(lines)


def _add_column(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    fields, sep = _fields(lines[k])
    j = draw(st.integers(0, len(fields)))
    fields.insert(j, draw(FIELD_VALUES).encode("utf-8", "surrogatepass"))
    lines[k] = sep.join(fields)
    return _join(lines)


def _drop_column(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    fields, sep = _fields(lines[k])
    if len(fields) > 1:
        del fields[draw(st.integers(0, len(fields) - 1))]
    lines[k] = sep.join(fields)
    return _join(lines)


def _delete_line(draw, data):
    lines = _split_lines(data)
    del lines[_pick_line(draw, lines)]
    return _join(lines)


def _duplicate_line(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    lines.insert(draw(st.integers(0, len(lines))), lines[k])
    return _join(lines)


def _swap_lines(draw, data):
    lines = _split_lines(data)
    a, b = _pick_line(draw, lines), _pick_line(draw, lines)
    lines[a], lines[b] = lines[b], lines[a]
    return _join(lines)


def _long_field(draw, data):
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    fields, sep = _fields(lines[k])
    j = draw(st.integers(0, len(fields) - 1))
    char = draw(st.sampled_from([b"9", b"a", b'"', b" ", b"1e9,"]))
    fields[j] = char * (LONG_FIELD // len(char) + draw(st.integers(0, 10)))
    lines[k] = sep.join(fields)
    return _join(lines)


def _line_endings(draw, data):
    kind = draw(st.sampled_from(["crlf", "cr", "strip_final", "double"]))
    if kind == "crlf":
        return data.replace(b"\n", b"\r\n")
    if kind == "cr":
        return data.replace(b"\n", b"\r")
    if kind == "strip_final":
        return data.rstrip(b"\n")
    return data.replace(b"\n", b"\n\n")


def _encoding(draw, data):
    kind = draw(st.sampled_from(["bom", "latin1", "utf16", "nul", "bom_twice"]))
    if kind == "bom":
        return b"\xef\xbb\xbf" + data
    if kind == "bom_twice":
        return b"\xef\xbb\xbf\xef\xbb\xbf" + data
    if kind == "latin1":
        i = draw(st.integers(0, len(data)))
        return data[:i] + "é°µ".encode("latin-1") + data[i:]
    if kind == "utf16":
        return data.decode("utf-8", "replace").encode("utf-16")
    i = draw(st.integers(0, len(data)))
    return data[:i] + b"\x00" + data[i:]


def _unicode(draw, data):
    i = draw(st.integers(0, len(data)))
    text = draw(st.text(min_size=1, max_size=6))
    return data[:i] + text.encode("utf-8", "surrogatepass") + data[i:]


def _numbers_scaled(draw, data):
    """Multiply every number on one line by a huge or tiny factor (keeps the syntax valid)."""
    lines = _split_lines(data)
    k = _pick_line(draw, lines)
    exponent = draw(st.sampled_from(["e300", "e306", "e-300", "e20", "e3"]))
    lines[k] = re.sub(rb"(?<![\w.])(\d+(\.\d+)?)(?![\w.])", lambda m: m.group(1) + exponent.encode(), lines[k])
    return _join(lines)


TEXT_OPS = (
    _replace_field,
    _replace_field,
    _replace_field,
    _empty_field,
    _add_column,
    _drop_column,
    _delete_line,
    _duplicate_line,
    _swap_lines,
    _long_field,
    _line_endings,
    _encoding,
    _unicode,
    _numbers_scaled,
) + BYTE_OPS


@st.composite
def mutated(draw, seeds, text: bool = True, max_mutations: int = 3) -> bytes:
    """A valid file from ``seeds`` (bytes or a sequence of bytes) with 1..``max_mutations`` mutations.

    ``text=False`` restricts to byte mutations (binary formats such as images).
    """
    if isinstance(seeds, (bytes, bytearray)):
        seeds = [bytes(seeds)]
    data = draw(st.sampled_from(list(seeds)))
    ops = TEXT_OPS if text else BYTE_OPS
    for _ in range(draw(st.integers(1, max_mutations))):
        data = draw(st.sampled_from(ops))(draw, data)
    return data
