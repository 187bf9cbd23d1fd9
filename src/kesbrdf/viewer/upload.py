"""Uploads to the viewer: the work check and the fit of a measurement CSV, as JSON.

These run inside the fit's child process (:mod:`kesbrdf.viewer.fit_job`), never in the
server process: parsing and fitting an upload is bounded by the fit's work budget.
"""

from __future__ import annotations

import base64
import json
import os
import re
import tempfile
from pathlib import Path

from kesbrdf._atomic import write_bytes
from kesbrdf.errors import KesbrdfError, ModelError
from kesbrdf.viewer.limits import ViewerLimits

__all__ = [
    "UploadTooLarge",
    "check_upload_work",
    "fit_csv_bytes",
    "measurement_to_json",
    "safe_upload_name",
]

_SAFE_NAME = re.compile(r"[^A-Za-z0-9._ -]+")


def _array_json(a) -> dict:
    """Encode a float array like the model file does (docs/formats.md)."""
    import numpy as np

    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {
        "dtype": "<f8",
        "shape": list(a.shape),
        "data": base64.b64encode(a.tobytes()).decode("ascii"),
    }


def measurement_to_json(measurement) -> dict:
    """Viewer-friendly measurement: angles in radians, f_r in 1/sr, arrays as in model files."""
    import numpy as np

    psi = measurement.psi
    return {
        "channels": list(measurement.channels),
        "theta_i": _array_json(measurement.theta_i),
        "phi_i": _array_json(measurement.phi_i),
        "theta_r": _array_json(measurement.theta_r),
        "phi_r": _array_json(measurement.phi_r),
        "values": _array_json(measurement.values),
        "psi": None if psi is None else _array_json(np.where(np.isnan(psi), -1.0, psi)),
        "metadata": {str(k): str(v) for k, v in dict(measurement.metadata).items()},
        "notes": [str(n) for n in measurement.notes],
    }


def safe_upload_name(name: str | None) -> str:
    base = os.path.basename((name or "upload.csv").replace("\\", "/")).strip()
    base = _SAFE_NAME.sub("_", base).lstrip(".") or "upload.csv"
    return base[:100]


def fit_csv_bytes(data: bytes, name: str = "upload.csv", fallback: str | None = None):
    """Read and fit an uploaded measurement CSV; return ``(model_json, measurement_json)``.

    The CSV is written to a private temporary folder under its (sanitised) upload
    name, so error messages read ``name.csv:12: ...`` exactly like
    ``kesbrdf fit name.csv`` would print them.
    """
    try:
        from kesbrdf.fitting import fit
        from kesbrdf.io.measurement_csv import read_measurement
    except ImportError as exc:  # pragma: no cover - core always ships these
        raise ModelError(f"fitting is not available in this installation: {exc}") from None
    safe = safe_upload_name(name)
    with tempfile.TemporaryDirectory(prefix="kesbrdf-view-") as tmp:
        csv_path = Path(tmp) / safe
        write_bytes(csv_path, data)
        prefix = str(Path(tmp)) + os.sep
        try:
            measurement = read_measurement(csv_path)
            # the same entry point and defaults as `kesbrdf fit`; fallback=error is --strict.
            # compare=False: the held-out comparison with the woven-cloth prior costs several
            # prior fits, beyond an upload's work budget (kesbrdf.viewer.limits); the viewer
            # draws any kind through its (phi, gamma) table view (view_document)
            model, _report = fit(measurement, strict=fallback == "error", compare=False)
            out = Path(tmp) / (Path(safe).stem + ".kes.json")
            model.save(out)
            model_doc = view_document(model, json.loads(out.read_text(encoding="utf-8")))
            info = model_doc.get("input")
            if isinstance(info, dict) and str(info.get("name", "")).startswith(prefix):
                info["name"] = safe  # the upload's name, not the temporary path
        except KesbrdfError as exc:
            # name the upload, not the private temporary folder
            message = str(exc).replace(prefix, "")
            try:
                renamed = type(exc)(message)
            except TypeError:  # a subclass with a different constructor
                renamed = KesbrdfError(message)
            raise renamed from None
    return model_doc, measurement_to_json(measurement)


def view_document(model, doc: dict | None = None) -> dict:
    """The model document the viewer's shaders draw: the (φ, γ) table format.

    A model with its own (φ, γ) table is sent as its file document (``doc`` when the
    caller has read it already); any other kind is sent as its tabulated view
    (``model.table_view()``, :func:`kesbrdf.models.table.tabulate`), with
    ``tabulated_from`` naming the model it was drawn from.
    """
    from kesbrdf.io.model_file import model_to_dict

    if model.has_table:
        return doc if doc is not None else model_to_dict(model)
    view = model_to_dict(model.table_view())
    view["tabulated_from"] = {"kind": model.kind, "description": model.describe()}
    return view


class UploadTooLarge(KesbrdfError):
    """An upload would cost more work or memory than the server allows (HTTP 413)."""


def check_upload_work(data: bytes, name: str = "upload.csv", limits: ViewerLimits | None = None):
    """Refuse an upload whose fit would cost more than the budget, before fitting it.

    Parses the CSV (the reader's errors, named ``name:line``, come out unchanged),
    checks its channels against ``limits.max_fit_channels``, picks the kind ``kesbrdf fit``
    would fit (:func:`kesbrdf.fitting.choose_fitter`) and checks rows x channels against
    that kind's budget (:meth:`ViewerLimits.values_budget`): a scattered fit costs far
    more per row than a grid one.  Returns the parsed measurement.

    Raises
    ------
    UploadTooLarge
        Too many channels, or too many values for the kind.
    KesbrdfError
        The CSV is malformed (same message as ``kesbrdf fit name``).
    """
    from kesbrdf.io.measurement_csv import parse_measurement
    from kesbrdf.io.text import decode_text

    limits = limits or ViewerLimits()
    measurement = parse_measurement(decode_text(data, name), source=name)
    n_channels = len(measurement.channels)
    if n_channels > limits.max_fit_channels:
        raise UploadTooLarge(
            f"{name}: expected at most {limits.max_fit_channels} channels for a fit in the viewer, "
            f"got {n_channels}; fit it with 'kesbrdf fit' and open the model file"
        )
    values = len(measurement) * n_channels
    if values > limits.max_fit_values:
        raise UploadTooLarge(
            f"{name}: expected at most {limits.max_fit_values} values (rows x channels) for a fit "
            f"in the viewer (kesbrdf view --max-fit-values N), got {values}"
        )
    from kesbrdf.fitting import choose_fitter

    kind = choose_fitter(measurement)[0]
    budget = limits.values_budget(kind)
    if values > budget:
        raise UploadTooLarge(
            f"{name}: expected at most {budget} values (rows x channels) for a {kind} fit in the viewer "
            f"(kesbrdf view --max-fit-values {kind}=N), got {values} ({len(measurement)} rows x {n_channels} "
            f"channels); fit it with 'kesbrdf fit {name}' and open the model file"
        )
    return measurement
