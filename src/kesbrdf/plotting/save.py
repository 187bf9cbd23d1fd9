"""Saving figures with their provenance (package version, input hash, parameters).

Every figure kesbrdf writes can be traced to its data (STYLE "Plots, CLI, renders"):

* PNG: one ``tEXt`` chunk per key: ``kesbrdf_version``, ``input_sha256``,
  ``parameters`` (JSON) and ``kesbrdf_provenance`` (the whole record as JSON);
* SVG: the Dublin Core block (``Creator`` = kesbrdf version, ``Source`` = input
  SHA-256, ``Description`` = the whole record as JSON);
* PDF: the info dictionary (``Creator``, ``Subject`` = the record as JSON,
  ``Keywords`` = ``input_sha256=...``).

No timestamps are written, so the same inputs give byte-identical SVG and PNG files.
Files are written atomically.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from kesbrdf._atomic import atomic_path
from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError

__all__ = [
    "FORMATS",
    "jsonable",
    "provenance",
    "describe",
    "figure_provenance",
    "attach_provenance",
    "save_figure",
    "figure_bytes",
    "read_png_text",
]

#: Output formats :func:`save_figure` writes, by file suffix.
FORMATS = ("png", "svg", "pdf")

_PROVENANCE_ATTR = "kesbrdf_provenance"


def jsonable(value):
    """Plain-JSON version of numbers, arrays, tuples and nested dicts."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return repr(value)


def describe(obj) -> str:
    """A stable one-line description of a reference BRDF: class name and its public
    scalar/list attributes (no memory address, unlike the default ``repr``).

    >>> class Ward:
    ...     def __init__(self): self.alpha_x = 0.1; self.channels = ("value",)
    >>> describe(Ward())
    "Ward(alpha_x=0.1, channels=('value',))"
    """
    if type(obj).__repr__ is not object.__repr__:
        return repr(obj)
    attrs = {
        k: v
        for k, v in sorted(vars(obj).items() if hasattr(obj, "__dict__") else [])
        if not k.startswith("_") and isinstance(v, (int, float, str, bool, tuple, list, np.ndarray, np.generic))
    }
    args = ", ".join(
        f"{k}={np.asarray(v).tolist() if isinstance(v, (np.ndarray, np.generic)) else v!r}" for k, v in attrs.items()
    )
    return f"{type(obj).__name__}({args})"


def provenance(model=None, measurement=None, reference=None, **parameters) -> dict:
    """The provenance record of a figure or report made from these inputs.

    Parameters
    ----------
    model : Model or None
        Its ``input_info`` (name, sha256 of the fitted measurement file) and
        ``parameters`` are recorded.
    measurement : Measurement or None
        Its ``source`` and ``sha256`` are recorded.
    reference : callable or None
        Its ``repr`` is recorded.
    **parameters
        Figure parameters (γ values, light direction, mapping, channel, ...).

    Returns
    -------
    dict
        ``{"kesbrdf_version", "input_sha256", "inputs", "model_parameters",
        "parameters"}``; ``input_sha256`` is the SHA-256 of the measurement file the
        model was fitted from (or of the plotted measurement when there is no model).
    """
    inputs: dict = {}
    input_sha256 = None
    if model is not None:
        info = dict(getattr(model, "input_info", None) or {})
        inputs["model"] = info
        input_sha256 = info.get("sha256")
    if measurement is not None:
        inputs["measurement"] = {
            "source": None if measurement.source is None else str(measurement.source),
            "sha256": measurement.sha256,
            "sample": measurement.metadata.get("sample"),
        }
        if input_sha256 is None:
            input_sha256 = measurement.sha256
    if reference is not None:
        inputs["reference"] = describe(reference)
    record = {
        "kesbrdf_version": __version__,
        "input_sha256": input_sha256,
        "inputs": inputs,
        "model_parameters": dict(getattr(model, "parameters", None) or {}),
        "parameters": parameters,
    }
    return jsonable(record)


def attach_provenance(fig, record: dict):
    """Store ``record`` on ``fig`` so :func:`save_figure` writes it; returns ``fig``."""
    setattr(fig, _PROVENANCE_ATTR, jsonable(record))
    return fig


def figure_provenance(fig) -> dict:
    """The provenance record attached to ``fig`` (empty dict if none)."""
    return dict(getattr(fig, _PROVENANCE_ATTR, None) or {})


def _format_of(path: Path, fmt: str | None) -> str:
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise KesbrdfError(
            f"{path}: expected a figure file ending in {', '.join('.' + f for f in FORMATS)}, "
            f"got {path.suffix or 'no suffix'!r}"
        )
    return fmt


def _metadata(fmt: str, record: dict) -> dict:
    text = json.dumps(record, sort_keys=True)
    sha = str(record.get("input_sha256"))
    creator = f"kesbrdf {record.get('kesbrdf_version', __version__)}"
    if fmt == "png":
        return {
            "Software": creator,
            "kesbrdf_version": str(record.get("kesbrdf_version", __version__)),
            "input_sha256": sha,
            "parameters": json.dumps(record.get("parameters", {}), sort_keys=True),
            "kesbrdf_provenance": text,
        }
    if fmt == "svg":
        return {"Creator": creator, "Source": sha, "Description": text, "Date": None}
    return {
        "Creator": creator,
        "Subject": text,
        "Keywords": f"input_sha256={sha}",
        "CreationDate": None,
    }


def figure_bytes(fig, fmt: str = "png", record: dict | None = None, dpi: int | None = None) -> bytes:
    """Render ``fig`` to bytes of ``fmt`` with its provenance metadata."""
    rec = figure_provenance(fig)
    rec.update(jsonable(record or {}))
    rec.setdefault("kesbrdf_version", __version__)
    import matplotlib

    buf = io.BytesIO()
    # a fixed salt makes SVG clip-path ids, and so the file, reproducible
    with matplotlib.rc_context({"svg.hashsalt": "kesbrdf"}):
        fig.savefig(buf, format=fmt, metadata=_metadata(fmt, rec), dpi=dpi)
    return buf.getvalue()


def save_figure(fig, path, record: dict | None = None, fmt: str | None = None, dpi: int | None = None) -> Path:
    """Write ``fig`` to ``path`` atomically, with provenance metadata.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or PathLike
        Output file; the format comes from its suffix (``.png``, ``.svg``, ``.pdf``)
        unless ``fmt`` is given.
    record : dict, optional
        Provenance merged over the one attached by :func:`attach_provenance`.

    Returns
    -------
    Path
    """
    path = Path(path)
    fmt = _format_of(path, fmt)
    data = figure_bytes(fig, fmt, record, dpi=dpi)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def read_png_text(data: bytes) -> dict:
    """The ``tEXt``/``iTXt`` chunks of PNG ``data`` as a dict (pure Python).

    >>> read_png_text(b"not a png")
    Traceback (most recent call last):
    ...
    kesbrdf.errors.KesbrdfError: expected PNG data (signature), got b'not a pn'
    """
    import struct
    import zlib

    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise KesbrdfError(f"expected PNG data (signature), got {data[:8]!r}")
    out: dict = {}
    pos = 8
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"tEXt":
            key, _, value = body.partition(b"\0")
            out[key.decode("latin-1")] = value.decode("latin-1")
        elif kind == b"iTXt":
            key, _, rest = body.partition(b"\0")
            compressed, _method = rest[0], rest[1]
            _lang, _, rest = rest[2:].partition(b"\0")
            _tkey, _, value = rest.partition(b"\0")
            if compressed:
                value = zlib.decompress(value)
            out[key.decode("latin-1")] = value.decode("utf-8")
        elif kind == b"zTXt":
            key, _, rest = body.partition(b"\0")
            out[key.decode("latin-1")] = zlib.decompress(rest[1:]).decode("latin-1")
        pos += 12 + length
    return out
