"""One small error hierarchy for kesbrdf.

Every user-facing error derives from :class:`KesbrdfError` and from
:class:`ValueError`, so callers that only know the standard library still catch
them.  Messages say what was expected, what arrived, and where (file and line
for file input).  The CLI prints ``str(error)`` on one line and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "KesbrdfError",
    "FormatError",
    "MeasurementError",
    "KESError",
    "ModelError",
    "ExportError",
    "where",
]


def where(path: object | None, line: int | None = None) -> str:
    """Return ``"path:line: "`` (or ``"path: "``, or ``""``) for error prefixes."""
    if path is None:
        return ""
    if line is None:
        return f"{path}: "
    return f"{path}:{line}: "


class KesbrdfError(ValueError):
    """Base class of all errors kesbrdf raises for bad input."""


class FormatError(KesbrdfError):
    """A file does not follow its documented format."""


class MeasurementError(KesbrdfError):
    """Measurements are inconsistent or insufficient for the requested use."""


class KESError(KesbrdfError):
    """The extended-KES interpolation is not defined for the given inputs."""


class ModelError(KesbrdfError):
    """A model file is unreadable, of an unknown version, or inconsistent."""


class ExportError(KesbrdfError):
    """An export cannot be written as asked (format, output path, options, model kind)."""
