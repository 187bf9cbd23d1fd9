"""Writing the model file (``docs/formats.md``): header, shared fields, arrays as base64.

The writer needs no registry: a model writes its own payload (``to_payload``), so
:meth:`kesbrdf.models.base.ReflectanceModel.save` can call it without an import loop.
Reading, which must look a kind up, is :mod:`kesbrdf.io.model_file`.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text

__all__ = ["save_model", "model_to_dict", "encode_array", "FORMAT", "FORMAT_VERSION"]

FORMAT = "kesbrdf-model"
FORMAT_VERSION = 1


def encode_array(a) -> dict:
    """``{"dtype": "<f8", "shape": [...], "data": base64}`` of a C-order little-endian copy."""
    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {"dtype": "<f8", "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


def model_to_dict(model) -> dict:
    """The model file document of any registered kind."""
    fields, arrays = model.to_payload()
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kesbrdf_version": model.kesbrdf_version,
        "kind": model.kind,
        "channels": list(model.channels),
        "input": model.input_info,
        "parameters": model.parameters,
        "diagnostics": model.diagnostics,
    }
    clash = set(fields) & (set(doc) | {"arrays"})
    if clash:
        raise RuntimeError(f"kind {model.kind!r}: payload fields {sorted(clash)} clash with the header")
    doc.update(fields)
    doc["arrays"] = {name: encode_array(a) for name, a in arrays.items()}
    return doc


def save_model(path, model) -> Path:
    """Write ``model`` to ``path`` atomically."""
    return write_text(path, json.dumps(model_to_dict(model), indent=1, allow_nan=False) + "\n")
