"""The fabric catalogue: one fabric per row (docs/batch.md "Catalogue").

A CSV file (local path or fsspec URL) with columns

``id`` (required)
    The fabric's name; also its output folder ``OUT/<id>/``.  Letters, digits, ``.``,
    ``_`` and ``-``; unique ignoring case (``A`` and ``a`` would share a folder on macOS
    and Windows); not starting with ``.``.  An id equal to a file the run writes in
    ``OUT`` (:data:`kesbrdf.batch.summary.OUTPUT_FILES`: ``summary.csv`` ..., ignoring
    case) fails that fabric (:func:`check_id`).
``input`` (required)
    A measurement CSV (``# kesbrdf-measurement: 1``) or an acquisition manifest
    (``# kesbrdf-manifest: 1``, frames beside it), as a path relative to the
    catalogue's folder or as an fsspec URL.
option columns (optional, empty cell = default)
    :data:`OPTION_COLUMNS`: ``reference`` and ``reference_params`` (the fabric's
    ground truth for validation, when it has one), ``kind``, ``orientations``,
    ``fallback``, ``body``, ``interpolation``, ``warp_deg``, ``mapping``.
metadata columns
    ``notes``, ``name``, ``description`` and any column starting with ``meta_`` are
    copied to the summary untouched.

Any other column is an error (a misspelt option must not be silently ignored).  A
folder works as a catalogue too: every ``*.csv`` in it (except ``catalog.csv``) and
every ``*/manifest.csv`` one level down is a fabric named after the file or folder.
Per-row option errors do not stop the batch: the fabric is reported failed with the
one-line message.
"""

from __future__ import annotations

import csv
import io
import json
import os
import posixpath
import re
from dataclasses import dataclass, field

from kesbrdf.errors import FormatError, where

__all__ = ["Fabric", "read_catalog", "check_id", "OPTION_COLUMNS", "DEFAULT_OPTIONS"]

#: Option column -> default (also the options a step's parameters are built from).
#: The fit options default to None, "not given": ``kesbrdf fit``'s own defaults, and
#: ``kind=auto`` then compares with the woven-cloth prior exactly as the command does.
#: A value here would count as an option given and switch that comparison off, so a
#: fabric would get another model in a batch than from ``kesbrdf fit`` (it did, until
#: 2026-12-03: docs/decisions.md, "A batch fits by kesbrdf fit's rule").
DEFAULT_OPTIONS: dict = {
    "reference": None,
    "reference_params": None,
    "kind": "auto",
    "orientations": None,
    "fallback": None,
    "body": None,
    "interpolation": None,
    "warp_deg": None,
    "mapping": None,
}
OPTION_COLUMNS = tuple(DEFAULT_OPTIONS)
META_COLUMNS = ("notes", "name", "description")
_ID = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9._-]{0,127}$")


@dataclass
class Fabric:
    """One catalogue row: what to process and with which options."""

    id: str
    input: str
    options: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    #: a one-line error found while reading the row (the fabric fails with it)
    error: str | None = None
    line: int | None = None


def check_id(fid: str, source=None, line: int | None = None) -> str | None:
    """The one-line error for a fabric id that names one of the run's own files in
    ``OUT`` (compared ignoring case), else None.

    >>> check_id("Summary.CSV", "cat.csv", 4)  # doctest: +ELLIPSIS
    "cat.csv:4: expected a fabric id other than the batch's own files in OUT (summary.csv, ...), got 'Summary.CSV'"
    """
    from kesbrdf.batch.summary import OUTPUT_FILES

    names = tuple(OUTPUT_FILES.values())
    if fid.casefold() in {n.casefold() for n in names}:
        return (f"{where(source, line)}expected a fabric id other than the batch's own files in OUT "
                f"({', '.join(names)}; ignoring case), got {fid!r}")
    return None


def _join(base: str, rel: str) -> str:
    if "://" in rel or os.path.isabs(rel):
        return rel
    if "://" in base:
        return posixpath.join(posixpath.dirname(base), rel)
    return os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(base)), rel))


def _parse_option(name: str, text: str):
    """Cell text -> option value; raises ValueError with the expectation."""
    if name in ("reference", "mapping"):
        return text
    if name == "reference_params":
        value = json.loads(text)
        if not isinstance(value, dict):
            raise ValueError(f"expected a JSON object, got {text!r}")
        return value
    if name == "kind":
        from kesbrdf.models.base import known_fitters  # the registry: every kind and fitter

        kinds = ("auto",) + known_fitters()
        if text not in kinds:
            raise ValueError(f"expected one of {', '.join(kinds)}, got {text!r}")
        return text
    if name == "orientations":
        if text not in ("3", "4"):
            raise ValueError(f"expected 3 or 4, got {text!r}")
        return int(text)
    if name == "fallback":
        if text not in ("error", "log"):
            raise ValueError(f"expected error or log, got {text!r}")
        return text
    if name == "body":
        if text in ("auto", "none"):
            return text
        try:
            return float(text)
        except ValueError:
            raise ValueError(f"expected auto, none or a number in 1/sr, got {text!r}") from None
    if name == "interpolation":
        if text not in ("kes", "nearest", "linear"):
            raise ValueError(f"expected kes, nearest or linear, got {text!r}")
        return text
    if name == "warp_deg":
        try:
            return float(text)
        except ValueError:
            raise ValueError(f"expected degrees, got {text!r}") from None
    raise ValueError(f"unknown option {name!r}")  # pragma: no cover


def parse_catalog(text: str, source: str = "<catalog>") -> list[Fabric]:
    """Parse catalogue CSV text; inputs are resolved relative to ``source``."""
    lines = [ln for ln in text.splitlines()]
    body = [(k + 1, ln) for k, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not body:
        raise FormatError(f"{where(source)}expected a catalogue CSV with columns id,input,...; got no rows")
    header_line, header_text = body[0]
    header = [h.strip() for h in next(csv.reader([header_text]))]
    for col in ("id", "input"):
        if col not in header:
            raise FormatError(f"{where(source, header_line)}expected a column {col!r}; got columns {', '.join(header)}")
    for col in header:
        if col not in ("id", "input", *OPTION_COLUMNS, *META_COLUMNS) and not col.startswith("meta_"):
            raise FormatError(
                f"{where(source, header_line)}unknown catalogue column {col!r}; expected id, input, "
                f"{', '.join(OPTION_COLUMNS)}, notes or meta_*"
            )
    fabrics: list[Fabric] = []
    seen: dict[str, int] = {}
    for lineno, row in ((ln, next(csv.reader([t]))) for ln, t in body[1:]):
        if len(row) > len(header):
            raise FormatError(f"{where(source, lineno)}expected {len(header)} cells, got {len(row)}")
        rec = {h: (row[k].strip() if k < len(row) else "") for k, h in enumerate(header)}
        fid = rec["id"]
        if not _ID.match(fid):
            raise FormatError(
                f"{where(source, lineno)}expected an id of letters, digits, '.', '_', '-' (a folder name), got {fid!r}"
            )
        first = seen.get(fid.casefold())
        if first is not None:
            as_ = "" if first[1] == fid else (f" as {first[1]!r}; ids differing only in case share a folder "
                                              "on macOS and Windows")
            raise FormatError(f"{where(source, lineno)}duplicate id {fid!r} (first on line {first[0]}{as_})")
        seen[fid.casefold()] = (lineno, fid)
        fab = Fabric(id=fid, input=_join(source, rec["input"]) if rec["input"] else "", line=lineno)
        fab.error = check_id(fid, source, lineno)
        if not rec["input"] and fab.error is None:
            fab.error = f"{where(source, lineno)}fabric {fid!r}: expected an input path, got an empty cell"
        for name in OPTION_COLUMNS:
            text = rec.get(name, "")
            if not text:
                continue
            try:
                fab.options[name] = _parse_option(name, text)
            except (ValueError, json.JSONDecodeError) as exc:
                fab.error = fab.error or f"{where(source, lineno)}column {name!r}: {exc}"
        fab.meta = {k: v for k, v in rec.items() if (k in META_COLUMNS or k.startswith("meta_")) and v}
        fabrics.append(fab)
    return fabrics


def _folder_catalog(path: str, fs) -> list[Fabric]:
    fabrics = []
    for entry in sorted(fs.ls(path, detail=True), key=lambda e: e["name"]):
        name = entry["name"].rstrip("/")
        base = posixpath.basename(name)
        if entry["type"] == "file" and base.endswith(".csv") and base != "catalog.csv":
            fid, inp = base[: -len(".csv")], name
        elif entry["type"] == "directory" and fs.exists(name + "/manifest.csv"):
            fid, inp = base, name + "/manifest.csv"
        else:
            continue
        fid = re.sub(r"[^A-Za-z0-9._-]", "_", fid).lstrip(".") or "fabric"
        fabrics.append(Fabric(id=fid, input=inp, error=check_id(fid, name)))
    ids = [f.id.casefold() for f in fabrics]
    dup = sorted({f.id for f in fabrics if ids.count(f.id.casefold()) > 1})
    if dup:
        raise FormatError(f"{where(path)}two inputs map to the same fabric id {dup[0]!r}; use a catalogue CSV")
    return fabrics


def read_catalog(source: str | os.PathLike, storage_options: dict | None = None) -> list[Fabric]:
    """Read a catalogue CSV or a folder of inputs (local path or fsspec URL)."""
    import fsspec

    source = str(source)
    fs, path = fsspec.core.url_to_fs(source, **(storage_options or {}))
    if not fs.exists(path):
        raise FileNotFoundError(2, "No such file or directory", source)
    if fs.isdir(path):
        fabrics = _folder_catalog(path, fs)
        if "://" in source:
            proto = fs.protocol[0] if isinstance(fs.protocol, tuple) else fs.protocol
            for f in fabrics:
                f.input = f"{proto}://{f.input}"
        if not fabrics:
            raise FormatError(f"{where(source)}expected measurement CSVs or */manifest.csv in the folder, found none")
        return fabrics
    if "file" in (fs.protocol if isinstance(fs.protocol, tuple) else (fs.protocol,)):
        from kesbrdf.io.files import read_regular

        data = read_regular(path)  # a FIFO or a device is refused, never read
    else:
        with fs.open(path, "rb") as fh:
            data = fh.read()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise FormatError(f"{where(source)}expected a UTF-8 catalogue CSV, got binary data") from None
    return parse_catalog(text, source)


def write_catalog(path, fabrics: list[Fabric]) -> None:
    """Write a catalogue CSV (inputs as given, options as their cell text)."""
    from kesbrdf._atomic import write_text

    cols = ["id", "input", *[c for c in OPTION_COLUMNS if any(c in f.options for f in fabrics)]]
    metas = sorted({k for f in fabrics for k in f.meta})
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols + metas)
    for f in fabrics:
        cells = [f.id, f.input]
        for c in cols[2:]:
            v = f.options.get(c)
            cells.append("" if v is None else (json.dumps(v, sort_keys=True) if isinstance(v, dict) else str(v)))
        cells += [f.meta.get(k, "") for k in metas]
        w.writerow(cells)
    write_text(path, buf.getvalue())
