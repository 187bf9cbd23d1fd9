"""Model kinds: the one interface every fitted model implements, and their registry.

A *kind* is a family of fitted models (``kes``, ``kes-halfdiff``, the scattered fit, the
woven-cloth prior, ...).  Each kind is one class deriving from :class:`ReflectanceModel`,
defined in its own module and registered with :func:`register`.  Everything that reads,
writes, evaluates or fits models goes through this interface, so a new kind slots in by
adding one module and one line in :data:`KIND_MODULES`.

The contract
------------
Class attributes:

``kind``
    The name written in model files (``"kes"``).
``mappings``
    The direction mappings :meth:`ReflectanceModel.evaluate` accepts, first = default.

Instance attributes (shared by every kind, written in every model file):
``channels`` (tuple of str), ``parameters`` (dict: how it was fitted), ``diagnostics``
(dict), ``input_info`` (dict: provenance of the measurement), ``kesbrdf_version``.

Methods:

``evaluate(wi, wr, mapping=None) -> ndarray (..., C)``
    f_r in 1/sr; directions are unit vectors in the fabric frame (x = warp), pointing
    away from the surface; 0 at or below the horizon.
``to_payload() -> (fields, arrays)``
    The kind's own JSON-able fields and named float arrays; the model file adds the
    header and the shared attributes (:mod:`kesbrdf.io.model_file`).
``from_payload(fields, arrays, shared, source) -> model`` (classmethod)
    The inverse; validates shapes and raises :class:`~kesbrdf.errors.ModelError`.
``fit_measurement(measurement, **options) -> model`` (classmethod)
    Fit this kind; options it does not know are an error.
``usable_rows(measurement) -> (mask, reason)`` (classmethod)
    Which rows this kind can use, and a one-line reason for the others.
"""

from __future__ import annotations

import importlib
from typing import ClassVar

import numpy as np

from kesbrdf._version import __version__
from kesbrdf.errors import ModelError, where

__all__ = ["ReflectanceModel", "register", "kind_class", "known_kinds", "KIND_MODULES"]

#: Where each kind's class lives; imported on first use so that a kind's heavy
#: dependencies are paid only by its users.  One line per kind.
KIND_MODULES: dict[str, str] = {
    "kes": "kesbrdf.model",
    "kes-halfdiff": "kesbrdf.halfdiff",
    "fibre-prior": "kesbrdf.prior_model",
}

_REGISTRY: dict[str, type] = {}


class ReflectanceModel:
    """Base class of every model kind (module docstring)."""

    kind: ClassVar[str] = ""
    mappings: ClassVar[tuple[str, ...]] = ()

    channels: tuple[str, ...]
    parameters: dict
    diagnostics: dict
    input_info: dict
    kesbrdf_version: str = __version__

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def default_mapping(self) -> str:
        return self.mappings[0]

    def check_mapping(self, mapping: str | None) -> str:
        """``mapping`` or the default; a one-line error for mappings this kind lacks."""
        if mapping is None:
            return self.default_mapping
        if mapping not in self.mappings:
            raise ModelError(
                f"a {self.kind!r} model supports mapping {', '.join(map(repr, self.mappings))}; "
                f"got {mapping!r}"
            )
        return mapping

    def evaluate(self, wi, wr, mapping: str | None = None) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def to_payload(self) -> tuple[dict, dict[str, np.ndarray]]:  # pragma: no cover
        raise NotImplementedError

    @classmethod
    def from_payload(cls, fields: dict, arrays: dict, shared: dict, source=None):  # pragma: no cover
        raise NotImplementedError

    @classmethod
    def fit_measurement(cls, measurement, **options):  # pragma: no cover
        raise NotImplementedError

    @classmethod
    def usable_rows(cls, measurement):  # pragma: no cover
        raise NotImplementedError

    def save(self, path):
        """Write the model file atomically (:mod:`kesbrdf.io.model_file`)."""
        from kesbrdf.io.model_file import save_model

        return save_model(path, self)


def register(cls: type) -> type:
    """Class decorator: add a :class:`ReflectanceModel` subclass to the registry."""
    if not cls.kind or not cls.mappings:
        raise RuntimeError(f"{cls.__name__}: a model kind needs 'kind' and 'mappings'")
    _REGISTRY[cls.kind] = cls
    return cls


def known_kinds() -> tuple[str, ...]:
    return tuple(KIND_MODULES)


def kind_class(name, source=None) -> type:
    """The class of kind ``name``; a one-line :class:`ModelError` naming the known kinds."""
    if not isinstance(name, str) or name not in KIND_MODULES:
        raise ModelError(
            f"{where(source)}expected model kind one of {', '.join(map(repr, KIND_MODULES))}, got {name!r}"
        )
    if name not in _REGISTRY:
        importlib.import_module(KIND_MODULES[name])
    if name not in _REGISTRY:
        raise RuntimeError(f"module {KIND_MODULES[name]} did not register kind {name!r}")
    return _REGISTRY[name]
