"""One small error hierarchy for kesbrdf.

Every user-facing error derives from :class:`KesbrdfError` and from
:class:`ValueError`, so callers that only know the standard library still catch
them.  Messages say what was expected, what arrived, and where (file and line
for file input).  The CLI prints ``str(error)`` on one line and exits non-zero.
"""

from __future__ import annotations

from typing import Iterable

__all__ = [
    "KesbrdfError",
    "FormatError",
    "MeasurementError",
    "KESError",
    "ModelError",
    "ExportError",
    "OutputError",
    "where",
    "validate_choice",
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


def validate_choice(
    name: str,
    value,
    choices: Iterable,
    source: object | None = None,
    line: int | None = None,
    error: type[KesbrdfError] = KesbrdfError,
):
    """Return ``value`` if it is one of ``choices``; otherwise raise ``error``.

    The one "expected one of ..." check of the package: the message names the
    option (``name``), lists the valid values, shows what arrived, and starts with
    ``source:line:`` when the value came from a file.

    Parameters
    ----------
    name : str
        What is being chosen, as the user knows it (``"protocol"``, ``"--mapping"``,
        ``"column kind"``).
    value : object
        The value to check (compared with ``==``, so strings match exactly).
    choices : iterable
        The valid values, in the order the message lists them.
    source, line : optional
        File and line the value was read from (see :func:`where`).
    error : subclass of KesbrdfError
        Error class to raise (``FormatError`` for file contents, ...).

    Examples
    --------
    >>> validate_choice("protocol", "paper", ("paper", "dense"))
    'paper'
    >>> validate_choice("protocol", "sparse", ("paper", "dense"))
    Traceback (most recent call last):
    ...
    kesbrdf.errors.KesbrdfError: protocol: expected one of paper, dense, got 'sparse'
    >>> validate_choice("column kind", "x", ("sample", "dark"), "m.csv", 3, FormatError)
    Traceback (most recent call last):
    ...
    kesbrdf.errors.FormatError: m.csv:3: column kind: expected one of sample, dark, got 'x'
    """
    choices = tuple(choices)
    try:
        ok = value in choices
    except TypeError:  # unhashable or incomparable value
        ok = False
    if ok:
        return value
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    listed = ", ".join(str(c) for c in choices)
    raise error(f"{where(source, line)}{name}: expected one of {listed}, got {shown}")
class ExportError(KesbrdfError):
    """An export cannot be written as asked (format, output path, options, model kind)."""


class OutputError(KesbrdfError):
    """An output cannot be written: disk full, read-only file system, name too long, ...

    Raised by :mod:`kesbrdf._atomic` from the :class:`OSError` of a failed write; the
    message names the target and the cause in words.  ``errno`` keeps the system's code.
    """

    def __init__(self, message: str, errno: int | None = None):
        super().__init__(message)
        self.errno = errno
