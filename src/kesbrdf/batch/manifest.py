"""Step manifests: what a finished step was computed from, and the skip rule.

Every step directory ``OUT/<fabric>/<step>/`` holds a ``manifest.json``::

    {"format": "kesbrdf-batch-step", "format_version": 1,
     "fabric": "f001", "step": "fit",
     "key": "<sha256 of the four fields below>",
     "inputs": {"measurement.csv": "<sha256>", ...},   # content hashes of the inputs
     "params": {...},                                   # the step's parameters
     "params_sha256": "<sha256>",
     "versions": {"kesbrdf": ..., "numpy": ..., "mitsuba": ...},
     "outputs": {"model.kes.json": "<sha256>", ...},   # content hashes of what it wrote
     "result": {...},                                   # small numbers for the summary
     "seconds": 0.012, "attempt_pid": 1234, "finished_unix": ...}

A rerun computes the key of each step from the content hashes of its inputs (for a
downstream step: the ``outputs`` of the upstream manifests), its parameters and the
versions that matter to it, and **skips the step when the stored manifest has the
same key** (docs/batch.md "Skip rules").  The manifest is written last, inside the
temporary step folder that is renamed into place, so a manifest never describes a
half-written folder.
"""

from __future__ import annotations

import functools
import hashlib
import json
from importlib import metadata

__all__ = ["MANIFEST", "FORMAT", "FORMAT_VERSION", "versions", "canonical_json", "sha256_bytes",
           "step_key", "make_manifest", "parse_manifest"]

MANIFEST = "manifest.json"
FORMAT = "kesbrdf-batch-step"
FORMAT_VERSION = 1
#: Steps whose results may depend on Mitsuba (the preview render; export formats that
#: build Mitsuba's warps): the Mitsuba version is part of their key.
MITSUBA_STEPS = frozenset({"preview", "export"})


def _dist_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


@functools.lru_cache(maxsize=1)
def _versions() -> tuple:
    import numpy

    from kesbrdf._version import __version__

    return (("kesbrdf", __version__), ("numpy", numpy.__version__), ("mitsuba", _dist_version("mitsuba")))


def versions() -> dict:
    """Versions recorded in every manifest (read from package metadata: no Mitsuba import)."""
    return dict(_versions())


def canonical_json(obj) -> str:
    """JSON with sorted keys and no whitespace: equal objects give equal text (and hash)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str, allow_nan=True)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def key_versions(step: str, vers: dict) -> dict:
    """The versions that invalidate ``step``: kesbrdf and numpy always, Mitsuba for
    :data:`MITSUBA_STEPS`."""
    keep = ("kesbrdf", "numpy", "mitsuba") if step in MITSUBA_STEPS else ("kesbrdf", "numpy")
    return {k: vers.get(k) for k in keep}


def step_key(step: str, inputs: dict, params: dict, vers: dict) -> str:
    """sha256 over (step, input hashes, parameters, relevant versions)."""
    doc = {"step": step, "inputs": inputs, "params": params, "versions": key_versions(step, vers)}
    return sha256_bytes(canonical_json(doc).encode())


def make_manifest(fabric: str, step: str, inputs: dict, params: dict, vers: dict, outputs: dict,
                  result: dict, seconds: float, **extra) -> dict:
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "fabric": fabric,
        "step": step,
        "key": step_key(step, inputs, params, vers),
        "inputs": inputs,
        "params": params,
        "params_sha256": sha256_bytes(canonical_json(params).encode()),
        "versions": vers,
        "outputs": outputs,
        "result": result,
        "seconds": seconds,
        **extra,
    }


def parse_manifest(data: bytes | None) -> dict | None:
    """A manifest dict, or None when absent or unreadable (then the step is recomputed)."""
    if not data:
        return None
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("format_version") != FORMAT_VERSION:
        return None
    return doc
