"""The export framework: one entry point that dispatches on :data:`kesbrdf.export.FORMATS`.

A format is a module (named in ``FORMATS``) providing

``export(model, out, **options) -> ExportResult``
    Write the file(s) for ``model`` at ``out`` atomically (:mod:`kesbrdf._atomic`) and say
    what was written and how well it agrees with the model.  Anything else (a dict, None)
    is refused with a one-line :class:`~kesbrdf.errors.ExportError`.
``EXTENSIONS`` (tuple of str, optional)
    The file name endings ``out`` may have (``(".bsdf",)``); checked *before* any work.
``HELP`` (str, optional)
    One line for ``kesbrdf export --list``.

:func:`export` loads ``model`` if it is a path, checks the format name, the output path
and the option names against the module's ``export`` signature, checks that the format
can hold the model's values (:func:`check_values`), calls it, and fills in the sizes of
the files written.
"""

from __future__ import annotations

import importlib
import inspect
import os
from dataclasses import dataclass, field
from pathlib import Path

from kesbrdf.errors import ExportError
from kesbrdf.export.registry import FORMATS

__all__ = ["ExportResult", "export", "format_module", "format_names", "check_output", "check_values",
           "VALUE_MAX"]

#: Largest f_r (1/sr) an export may have to write: the largest float32, the number type
#: of every target — GPU shaders (glTF, MaterialX, USD, BRDF Explorer), tensor files
#: (.bsdf), the renderers.  A format module may declare its own ``VALUE_MAX``.
VALUE_MAX = 3.4028234663852886e38


@dataclass
class ExportResult:
    """What an export wrote and how faithful it is.

    Attributes
    ----------
    format : str
        The format name (a key of ``FORMATS``).
    paths : list of Path
        Every file written, main file first.
    size : int
        Total bytes of ``paths`` (filled in by :func:`export`).
    agreement : dict
        Named numbers comparing the export with the model (e.g. ``median_rel_err``);
        empty when the format stores the model exactly or nothing was measured.
    notes : list of str
        One-line remarks: what is exact, what is approximate, caveats.
    open_with : str
        Where the file can be opened, e.g. ``'Mitsuba 3: <bsdf type="measured">'``.
    """

    format: str
    paths: list = field(default_factory=list)
    size: int = 0
    agreement: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    open_with: str = ""

    def to_json(self) -> dict:
        return {
            "format": self.format,
            "paths": [str(p) for p in self.paths],
            "size": int(self.size),
            "agreement": dict(self.agreement),
            "notes": list(self.notes),
            "open_with": self.open_with,
        }


def _jsonable(v):
    """Plain JSON values of a format's report (numpy scalars and arrays become numbers and lists)."""
    import json

    return json.loads(json.dumps(v, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def format_names() -> tuple[str, ...]:
    return tuple(FORMATS)


def format_module(fmt: str):
    """The module implementing format ``fmt``; a one-line error naming the known formats."""
    if not isinstance(fmt, str) or fmt not in FORMATS:
        known = ", ".join(map(repr, FORMATS)) or "(none installed)"
        raise ExportError(f"expected an export format, one of {known}; got {fmt!r}")
    name = FORMATS[fmt]
    if "." not in name:
        name = f"kesbrdf.export.{name}"
    return importlib.import_module(name)


def check_output(fmt: str, module, out) -> Path:
    """Check ``out`` before any work: a file path (not a folder) with an allowed ending."""
    out = Path(out)
    if str(out) == "" or out.name in ("", ".", ".."):
        raise ExportError(f"{fmt}: expected an output file path, got {str(out)!r}")
    if out.is_dir():
        raise ExportError(f"{fmt}: expected an output file path, got the folder {out}")
    exts = tuple(getattr(module, "EXTENSIONS", ()) or ())
    if exts and not out.name.lower().endswith(tuple(e.lower() for e in exts)):
        raise ExportError(f"{fmt}: expected an output file ending in {' or '.join(exts)}, got {out.name!r}")
    parent = out.parent if str(out.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise ExportError(f"{fmt}: expected a folder for the output, but {parent} is a file")
    if parent.exists() and not os.access(parent, os.W_OK):
        raise PermissionError(13, "Permission denied", str(parent))
    return out


def _check_options(fmt: str, module, options: dict) -> None:
    sig = inspect.signature(module.export)
    params = list(sig.parameters.values())[2:]
    if any(p.kind is p.VAR_KEYWORD for p in params):
        return
    known = [p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    unknown = [k for k in options if k not in known]
    if unknown:
        raise ExportError(
            f"{fmt}: unknown option(s) {', '.join(map(repr, unknown))}; "
            f"expected {', '.join(map(repr, known)) or 'none'}"
        )


def _load_model(model):
    if isinstance(model, (str, os.PathLike)):
        path = Path(model)
        if not path.is_file():
            raise FileNotFoundError(2, "No such file or directory", str(path))
        from kesbrdf.io.model_file import load_model as load

        return load(path)
    return model


def check_values(model, fmt: str, module=None, source=None) -> None:
    """Refuse, in one line, a model the format cannot write faithfully.

    The model's arrays must hold what a model file may hold (finite, magnitude at most
    :data:`kesbrdf.io.text.MAX_ABS_NUMBER`, NaN only where the kind allows it: the
    checks of :func:`kesbrdf.io.model_file.model_from_dict`), and its largest f_r —
    at most (largest tabulated value) / :data:`kesbrdf.models.mappings.COS_EPS`, reached at
    grazing angles — must fit the format's ``VALUE_MAX`` (default :data:`VALUE_MAX`).
    Objects that are not model kinds (a reference BRDF given to an analytic fit) pass.

    Raises
    ------
    ExportError
        ``FMT: cannot export SOURCE: ...`` naming the array and the value.
    """
    import numpy as np

    from kesbrdf.errors import ModelError
    from kesbrdf.models.mappings import COS_EPS

    if not hasattr(model, "to_payload"):
        return
    from kesbrdf.io.model_file import model_from_dict, model_to_dict

    name = source or "the model"
    try:
        model_from_dict(model_to_dict(model))
    except ModelError as exc:
        raise ExportError(f"{fmt}: cannot export {name}: {exc}") from None
    limit = float(getattr(module, "VALUE_MAX", VALUE_MAX))
    _, arrays = model.to_payload()
    for key, a in arrays.items():
        a = np.asarray(a, float)
        finite = a[np.isfinite(a)]
        peak = float(np.max(np.abs(finite))) if finite.size else 0.0
        if peak / COS_EPS > limit:
            raise ExportError(
                f"{fmt}: cannot export {name}: array {key!r} holds {peak:.3g}, so f_r reaches "
                f"{peak / COS_EPS:.3g} 1/sr at grazing angles, beyond the format's range {limit:.3g}"
            )


def export(model, fmt: str, out, **options) -> ExportResult:
    """Export ``model`` in format ``fmt`` to ``out`` (``docs/exports.md``).

    Parameters
    ----------
    model : ReflectanceModel or path
        A fitted model (any kind :func:`kesbrdf.models.brdf.evaluate` accepts) or a model file.
    fmt : str
        A key of :data:`kesbrdf.export.FORMATS`.
    out : str or Path
        The main output file; its ending must be one of the format's ``EXTENSIONS``.
    **options
        Passed to the format's ``export``; unknown names are an error before any work.

    Returns
    -------
    ExportResult

    Raises
    ------
    ExportError
        Unknown format, bad output path, unknown option, a model the format cannot hold
        (:func:`check_values`).
    """
    module = format_module(fmt)
    out = check_output(fmt, module, out)
    _check_options(fmt, module, options)
    source = str(model) if isinstance(model, (str, os.PathLike)) else None
    model = _load_model(model)
    check_values(model, fmt, module, source)
    result = module.export(model, out, **options)
    if not isinstance(result, ExportResult):  # the one contract of a format module
        raise ExportError(f"{fmt}: expected the format's export() to return an ExportResult, "
                          f"got {type(result).__name__} (from {module.__name__})")
    result.format = result.format or fmt
    result.paths = [Path(p) for p in (result.paths or [out])]
    result.agreement = _jsonable(result.agreement)
    result.size = sum(p.stat().st_size for p in result.paths if p.is_file())
    return result
