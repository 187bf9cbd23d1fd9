"""The model file: one JSON document, arrays inline as base64 (``docs/formats.md``).

This module handles what every kind shares — the header (``format``,
``format_version``, ``kind``), the shared fields (``channels``, ``input``,
``parameters``, ``diagnostics``, ``kesbrdf_version``) and the array codec — and looks
the kind's class up in the registry (:mod:`kesbrdf.models.base`); it knows no model class.
The kind's ``from_payload`` checks its own arrays (shapes, grids, values).

No pickle anywhere: ``load_model(save_model(m))`` rebuilds an identical model from
plain JSON and raw little-endian bytes.  Every malformed file gives a one-line
:class:`~kesbrdf.errors.ModelError` naming it: types and shapes are checked before
any allocation, nesting is bounded, and every number — JSON field or array element —
must be finite and of magnitude at most :data:`~kesbrdf.io.text.MAX_ABS_NUMBER` (the
bound of the CSV readers), so no product in evaluation or export overflows.  NaN is
allowed only in arrays whose kind gives it a meaning (``q_nodes``: unmeasured).
"""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np

from kesbrdf._version import __version__
from kesbrdf.errors import ModelError, where
from kesbrdf.io.files import open_regular
from kesbrdf.io.text import MAX_ABS_NUMBER
from kesbrdf.io.model_writer import FORMAT, FORMAT_VERSION, encode_array, model_to_dict, save_model
from kesbrdf.models.base import kind_class

__all__ = [
    "save_model",
    "load_model",
    "model_to_dict",
    "model_from_dict",
    "encode_array",
    "decode_array",
    "FORMAT",
    "FORMAT_VERSION",
    "MAX_ARRAY_ELEMENTS",
    "MAX_FILE_BYTES",
    "MAX_DEPTH",
]

#: Most array elements a model file may hold, in one array and in all together: 2**24
#: doubles = 128 MiB.  The largest table kesbrdf fits is a kes-halfdiff at the finest
#: 1° θ step, 360 × 91 × 91 × 3 channels ≈ 8.9 million (docs/formats.md).
MAX_ARRAY_ELEMENTS = 1 << 24
#: Largest model file read (bytes): the base64 text of MAX_ARRAY_ELEMENTS doubles
#: (171 MiB) plus room for the JSON fields.  Loading costs about 3× the file size.
MAX_FILE_BYTES = 192 << 20
#: Deepest JSON nesting accepted (the writer's deepest is ~6).
MAX_DEPTH = 64
#: Array dtypes accepted on reading (the writer writes ``<f8``).
DTYPES = ("<f8", "<f4")
_BOUND = f"{MAX_ABS_NUMBER:g}".replace("e+", "e")  # "1e100"
_SHARED = ("channels", "input", "parameters", "diagnostics")


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def decode_array(obj, name: str = "array", source=None) -> np.ndarray:
    """Inverse of :func:`encode_array`; every malformed entry is a one-line ModelError.

    The shape is validated (list of non-negative ints, at most
    :data:`MAX_ARRAY_ELEMENTS` elements) and the base64 length checked against it
    before anything is decoded or allocated.
    """
    prefix = f"{where(source)}array {name!r}: "
    if not isinstance(obj, dict):
        raise ModelError(f"{prefix}expected an object with dtype, shape and data, got {type(obj).__name__}")
    dtype, shape, data = obj.get("dtype"), obj.get("shape"), obj.get("data")
    if not isinstance(dtype, str) or dtype not in DTYPES:
        raise ModelError(f"{prefix}expected dtype one of {', '.join(DTYPES)}, got {str(dtype)[:40]!r}")
    if not isinstance(shape, list) or len(shape) > 8 or not all(_is_int(s) and s >= 0 for s in shape):
        raise ModelError(f"{prefix}expected shape a list of at most 8 non-negative integers, got {str(shape)[:60]}")
    count = math.prod(shape)
    # zero-length dimensions do not excuse the others: numpy refuses shapes whose
    # non-zero extents overflow, even for an empty array
    if math.prod(max(s, 1) for s in shape) > MAX_ARRAY_ELEMENTS:
        raise ModelError(f"{prefix}expected at most {MAX_ARRAY_ELEMENTS} elements, got shape {shape}")
    if not isinstance(data, str):
        raise ModelError(f"{prefix}expected base64 text data, got {type(data).__name__}")
    itemsize = np.dtype(dtype).itemsize
    n_bytes = count * itemsize
    if len(data) != 4 * ((n_bytes + 2) // 3):
        raise ModelError(f"{prefix}expected {n_bytes} bytes of data for shape {shape}, got {len(data)} base64 characters")
    try:
        raw = base64.b64decode(data, validate=True)
    except (ValueError, TypeError):
        raise ModelError(f"{prefix}expected base64 data, got invalid characters or padding") from None
    if len(raw) != n_bytes:
        raise ModelError(f"{prefix}expected {n_bytes} bytes for shape {shape}, got {len(raw)}")
    a = np.frombuffer(raw, dtype=dtype).reshape(shape).astype(float)
    del raw
    with np.errstate(invalid="ignore"):
        bad = np.abs(a) > MAX_ABS_NUMBER  # ±inf included; NaN is the kind's to judge
    if bad.any():
        where_bad = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ModelError(f"{prefix}expected finite values of magnitude at most {_BOUND}, got "
                         f"{float(a[where_bad])!r} at index {list(where_bad)} ({int(bad.sum())} such value(s))")
    return a


def _field_name(path: tuple) -> str:
    """``parameters.body``, ``support.psi_deg[2]``; a key with a newline or another
    unprintable character is quoted as JSON (``."a\\nb"``), so the message stays one line."""
    return "".join(f"[{p}]" if isinstance(p, int) else f".{p if str(p).isprintable() else json.dumps(p)}"
                   for p in path).lstrip(".")[:120] or "document"


def _check_tree(doc, source) -> None:
    """Nesting depth and the range of every JSON number, iteratively (no recursion on hostile input).

    The first bad number gives a one-line ModelError naming its field (``parameters.body``,
    ``prior.theta.alpha``, ``support.psi_deg[2]``); array data (base64 text) is checked
    by :func:`decode_array`.
    """
    stack = [(doc, ())]
    while stack:
        node, path = stack.pop()
        if len(path) >= MAX_DEPTH:
            raise ModelError(f"{where(source)}expected JSON nested at most {MAX_DEPTH} deep, got deeper")
        if isinstance(node, dict):
            stack.extend((v, path + (str(k),)) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, path + (i,)) for i, v in enumerate(node))
        elif isinstance(node, (int, float)) and not isinstance(node, bool):
            if not (math.isfinite(node) and abs(node) <= MAX_ABS_NUMBER):
                if isinstance(node, int):
                    shown = f"an integer of {len(str(abs(node)))} digits"
                else:  # JSON has no inf: a non-finite float is a number text that overflowed
                    shown = repr(node) if math.isfinite(node) else "a number that overflows a double"
                raise ModelError(f"{where(source)}{_field_name(path)}: expected a finite number of magnitude "
                                 f"at most {_BOUND}, got {shown}")


def load_model(path):
    """Read a model file of any registered kind; errors name the file."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError:
        size = 0
    if size > MAX_FILE_BYTES:
        raise ModelError(f"{where(path)}expected a model file of at most {MAX_FILE_BYTES} bytes, got {size}")
    with open_regular(path) as fh:  # bounded read: a file that grows, a FIFO, /dev/zero
        raw = fh.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise ModelError(f"{where(path)}expected a model file of at most {MAX_FILE_BYTES} bytes, got more")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ModelError(f"{where(path)}expected a kesbrdf model file (JSON), got binary data") from None
    del raw  # peak memory: the text, the parsed document and one decoded array at a time
    doc = _parse(text, path)
    del text
    return model_from_dict(doc, source=path)


def _no_constant(name):
    raise ValueError(f"{name} is not valid JSON")


def model_from_text(text: str, source=None):
    """Parse and check a model document given as text."""
    return model_from_dict(_parse(text, source), source=source)


def _parse(text: str, source=None):
    """The JSON document of ``text``; a one-line ModelError for anything that is not JSON."""
    try:
        doc = json.loads(text, parse_constant=_no_constant)  # numbers: range-checked by field
    except json.JSONDecodeError as exc:
        raise ModelError(
            f"{where(source, exc.lineno)}expected a kesbrdf model file (JSON), got invalid JSON: {exc.msg}"
        ) from None
    except RecursionError:
        raise ModelError(f"{where(source)}expected JSON nested at most {MAX_DEPTH} deep, got deeper") from None
    except ValueError as exc:  # NaN/Infinity constants, huge integers
        raise ModelError(f"{where(source)}expected a kesbrdf model file (JSON), got {exc}") from None
    return doc


def model_from_dict(doc, source=None):
    """Check the header and shared fields, decode the arrays, and let the kind rebuild."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ModelError(f"{where(source)}expected format {FORMAT!r}, got {str(got)[:60]!r}")
    _check_tree(doc, source)
    version = doc.get("format_version")
    if not _is_int(version) or version != FORMAT_VERSION:
        raise ModelError(f"{where(source)}expected model format version {FORMAT_VERSION}, got {repr(version)[:40]}")
    cls = kind_class(doc.get("kind", "kes"), source)
    arrays_doc = doc.get("arrays", {})
    if not isinstance(arrays_doc, dict):
        raise ModelError(f"{where(source)}arrays: expected a JSON object, got {type(arrays_doc).__name__}")
    missing = [a for a in cls.array_names if a not in arrays_doc]
    if missing:
        raise ModelError(f"{where(source)}missing array(s) {', '.join(missing)} of a {cls.kind!r} model")
    channels = doc.get("channels")
    if not isinstance(channels, list) or not channels or not all(isinstance(c, str) and c for c in channels):
        raise ModelError(f"{where(source)}channels: expected a non-empty list of names, got {str(channels)[:60]}")
    if len(set(channels)) != len(channels):
        raise ModelError(f"{where(source)}channels: expected distinct names, got {channels[:8]}")
    shared = {"channels": tuple(channels)}
    for key, attr in (("input", "input_info"), ("parameters", "parameters"), ("diagnostics", "diagnostics")):
        value = doc.get(key, {})
        if not isinstance(value, dict):
            raise ModelError(f"{where(source)}{key}: expected a JSON object, got {type(value).__name__}")
        shared[attr] = value
    version_text = doc.get("kesbrdf_version", __version__)
    if not isinstance(version_text, str):
        raise ModelError(f"{where(source)}kesbrdf_version: expected text, got {type(version_text).__name__}")
    shared["kesbrdf_version"] = version_text
    total = 0
    arrays = {}
    for name, entry in arrays_doc.items():
        arrays[name] = decode_array(entry, name, source)
        total += arrays[name].size
        if total > MAX_ARRAY_ELEMENTS:
            raise ModelError(f"{where(source)}expected at most {MAX_ARRAY_ELEMENTS} array elements in all")
    fields = {k: v for k, v in doc.items() if k not in ("format", "format_version", "kind", "kesbrdf_version",
                                                         "arrays", *_SHARED)}
    return cls.from_payload(fields, arrays, shared, source)
