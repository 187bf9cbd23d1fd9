"""The model file: one JSON document, arrays inline as base64 (``docs/formats.md``).

No pickle anywhere: ``load_model(save_model(m))`` rebuilds an identical model from
plain JSON and raw little-endian bytes.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text
from kesbrdf._version import __version__
from kesbrdf.errors import ModelError, where

__all__ = ["save_model", "load_model", "encode_array", "decode_array", "FORMAT", "FORMAT_VERSION"]

FORMAT = "kesbrdf-model"
FORMAT_VERSION = 1
ARRAYS = ("phi_grid", "gamma_grid", "table", "body", "gamma_nodes", "q_nodes")


def encode_array(a) -> dict:
    """``{"dtype": "<f8", "shape": [...], "data": base64}`` of a C-order little-endian copy."""
    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {"dtype": "<f8", "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


def decode_array(obj: dict, name: str = "array", source=None) -> np.ndarray:
    """Inverse of :func:`encode_array`, with clear errors for malformed entries."""
    try:
        dtype = np.dtype(obj["dtype"])
        shape = tuple(int(s) for s in obj["shape"])
        raw = base64.b64decode(obj["data"], validate=True)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"{where(source)}array {name!r}: expected dtype/shape/base64 data, got {exc}") from None
    if dtype.kind != "f":
        raise ModelError(f"{where(source)}array {name!r}: expected a float dtype, got {dtype}")
    expected = int(np.prod(shape)) * dtype.itemsize
    if len(raw) != expected:
        raise ModelError(f"{where(source)}array {name!r}: expected {expected} bytes for shape {shape}, got {len(raw)}")
    return np.frombuffer(raw, dtype=dtype).reshape(shape).astype(float)


def model_to_dict(model) -> dict:
    if getattr(model, "kind", "kes") == "kes-halfdiff":
        from kesbrdf.halfdiff import to_dict

        return to_dict(model)
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kesbrdf_version": model.kesbrdf_version,
        "kind": model.kind,
        "channels": list(model.channels),
        "input": model.input_info,
        "parameters": model.parameters,
        "diagnostics": model.diagnostics,
        "arrays": {name: encode_array(getattr(model, name)) for name in ARRAYS},
    }


def save_model(path, model) -> Path:
    """Write ``model`` to ``path`` atomically."""
    return write_text(path, json.dumps(model_to_dict(model), indent=1, allow_nan=False) + "\n")


def load_model(path):
    """Read a model file; errors name the file."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ModelError(f"{where(path)}expected a kesbrdf model file (JSON), got binary data") from None
    except json.JSONDecodeError as exc:
        raise ModelError(f"{where(path, exc.lineno)}expected a kesbrdf model file (JSON), got invalid JSON: {exc.msg}") from None
    return model_from_dict(doc, source=path)


def model_from_dict(doc, source=None):
    from kesbrdf.model import Model

    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ModelError(f"{where(source)}expected format {FORMAT!r}, got {got!r}")
    version = doc.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelError(f"{where(source)}expected model format version {FORMAT_VERSION}, got {version!r}")
    if doc.get("kind") == "kes-halfdiff":
        from kesbrdf.halfdiff import from_dict

        return from_dict(doc, source)
    arrays = doc.get("arrays", {})
    missing = [a for a in ARRAYS if a not in arrays]
    if missing:
        raise ModelError(f"{where(source)}missing array(s) {', '.join(missing)}")
    arr = {name: decode_array(arrays[name], name, source) for name in ARRAYS}
    channels = tuple(doc.get("channels", ()))
    n_phi, n_gamma = arr["phi_grid"].size, arr["gamma_grid"].size
    if arr["table"].shape != (n_phi, n_gamma, len(channels)) or arr["body"].shape != (len(channels),):
        raise ModelError(
            f"{where(source)}expected table of shape ({n_phi}, {n_gamma}, {len(channels)}) and body of "
            f"shape ({len(channels)},), got {arr['table'].shape} and {arr['body'].shape}"
        )
    return Model(
        channels=channels,
        kind=doc.get("kind", "kes"),
        parameters=doc.get("parameters", {}),
        diagnostics=doc.get("diagnostics", {}),
        input_info=doc.get("input", {}),
        kesbrdf_version=doc.get("kesbrdf_version", __version__),
        **arr,
    )
