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

A kind implements ``evaluate_unit(wi, wr, mapping) -> (n, C)``, its core: the base
class's :meth:`ReflectanceModel.evaluate` checks the mapping and hands the core only
clean pairs (unit rows above the horizon, in chunks) through
:func:`kesbrdf.models.mappings.evaluate_pairs`, which supplies the zeros and NaNs.

Fitters and automatic selection
-------------------------------
:func:`kesbrdf.fit` (``kesbrdf.fitting``) chooses among *fitters*: every kind is one
(its class's ``fit_measurement``), and a fitting method that produces an existing kind
(the scattered fit, which yields a ``kes`` model with a recorded sample-frame warp) is
one too, registered with :func:`register_fitter`.  :data:`FIT_MODULES` says where each
lives and :data:`AUTO_CANDIDATES` is the order ``kind="auto"`` tries them in: the first
candidate that uses every row wins, else the one that uses most (docs/models.md).
A new kind joins automatic selection with one entry in each.  A fitter's
``auto_compare`` (``"loo"``, ``"kfold"``, ``"dense"`` or None) says how ``kind="auto"``
checks its choice on the user's data (:func:`kesbrdf.fit`).

Capabilities: consumers ask, never compare kind names
----------------------------------------------------
Figures, the report, validation, the renderer, the exports and the viewer ask a model
what it can do (as pbrt-v4's ``BxDF::Flags()``), so every registered kind works in each
of them and a new kind needs no edit outside its own module:

``describe() -> str``
    One line naming the model (kind, table or parameters, channels).
``table_view(n_phi=None, n_gamma=None)``
    The tabulated lobe q(φ, γ) (:mod:`kesbrdf.models.table`), a model of the ``kes``
    kind: a kind with a (φ, γ) table returns it, every other kind is tabulated through
    ``evaluate`` (:func:`kesbrdf.models.table.tabulate`).  ``has_table`` says which.
``has_sigma``, ``predict_sigma(wi, wr)``
    A per-prediction σ: ``(f, σ, σ_ln f)``, or None for kinds that carry none.
``render_plugin(mapping=None, extrapolation=None) -> (plugin, props)``
    The Mitsuba plugin that draws the model and the properties it takes; the base class
    answers the ``kesbrdf`` table plugin, which draws the tabulated view.  An option the
    plugin cannot honour is a one-line :class:`~kesbrdf.errors.ModelError`.
``refit(mask, measurement=None)``
    The same fit (same fitter, same recorded options) on the rows ``mask`` of the
    measurement, for leave-one-out validation.  The measurement is the one the model was
    fitted to in this session (:meth:`ReflectanceModel.remember_fit`) or one passed in; a model read
    from a file holds no samples, so without one it is a one-line ModelError.
``sample_frame_warp``
    Azimuth of the warp in the measurement's frame (radians; 0 for fabric-frame fits).

Where a view genuinely cannot be drawn, the consumer raises a one-line
:class:`~kesbrdf.errors.ModelError` (exit 2 from the CLI) and the rest still runs.
"""

from __future__ import annotations

import importlib
from typing import ClassVar

import numpy as np

from kesbrdf._version import __version__
from kesbrdf.errors import ModelError, where
from kesbrdf.models.mappings import evaluate_pairs

__all__ = [
    "ReflectanceModel",
    "check_fit_options",
    "register",
    "register_fitter",
    "kind_class",
    "fitter_class",
    "known_kinds",
    "known_fitters",
    "KIND_MODULES",
    "FIT_MODULES",
    "AUTO_CANDIDATES",
    "TABLE_KIND",
]

#: Where each kind's class lives; imported on first use so that a kind's heavy
#: dependencies are paid only by its users.  One line per kind.
KIND_MODULES: dict[str, str] = {
    "kes": "kesbrdf.models.kes",
    "kes-halfdiff": "kesbrdf.models.halfdiff",
    "fibre-prior": "kesbrdf.models.fibre_prior",
    "fibre-coord": "kesbrdf.models.fibre_coord",
}

#: Where each fitter lives: every kind, plus fitting methods that produce an existing
#: kind (``scattered`` builds a ``kes`` model).  One line per fitter.
FIT_MODULES: dict[str, str] = {
    **KIND_MODULES,
    "scattered": "kesbrdf.models.scattered",
}

#: The order in which ``kesbrdf.fit(m, kind="auto")`` tries the fitters: the first that
#: uses every row wins, else the one that uses the most (ties: the earlier).  Simpler
#: models first, so the paper's protocol gets the paper's kind.
AUTO_CANDIDATES: list[str] = ["kes", "kes-halfdiff", "scattered"]

#: The kind whose models are the (φ, γ) table format (:mod:`kesbrdf.models.table`):
#: :meth:`ReflectanceModel.table_view` returns one, built by its class's ``tabulate``.
TABLE_KIND = "kes"

_REGISTRY: dict[str, type] = {}
_FITTERS: dict[str, type] = {}


class ReflectanceModel:
    """Base class of every model kind (module docstring)."""

    kind: ClassVar[str] = ""
    mappings: ClassVar[tuple[str, ...]] = ()
    #: Names of the keyword options ``fit_measurement`` accepts (``kesbrdf.fit`` rejects
    #: the others with a one-line error).
    fit_options: ClassVar[tuple[str, ...]] = ()
    #: How ``kind="auto"`` checks this fitter's choice on the user's data: ``"loo"``
    #: (leave-one-orientation-out against the prior), ``"kfold"``, ``"dense"`` (the dense
    #: rule of :func:`kesbrdf.fit`) or None (module docstring).
    auto_compare: ClassVar[str | None] = None
    #: Names of the arrays ``to_payload`` writes and ``from_payload`` needs.
    array_names: ClassVar[tuple[str, ...]] = ()

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

    @property
    def warnings(self) -> list[str]:
        """One-line warnings recorded when the model was fitted (``diagnostics["warnings"]``)."""
        w = self.diagnostics.get("warnings", []) if isinstance(self.diagnostics, dict) else []
        return [str(x) for x in w] if isinstance(w, list) else []

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

    def evaluate(self, wi, wr, mapping: str | None = None) -> np.ndarray:
        """f_r(wi, wr) in 1/sr, shape broadcast(wi, wr)[:-1] + (C,).

        Directions need not be normalised; a pair at or below the horizon
        (cos θ ≤ :data:`kesbrdf.models.mappings.COS_EPS`, or a zero vector) gives 0, a pair
        with a non-finite component gives NaN (:func:`kesbrdf.models.mappings.evaluate_pairs`).
        """
        mapping = self.check_mapping(mapping)
        return evaluate_pairs(self.evaluate_unit, wi, wr, self.n_channels, mapping)

    def evaluate_unit(self, wi, wr, mapping: str) -> np.ndarray:  # pragma: no cover
        """The kind's core: unit rows (n, 3) above the horizon -> f_r (n, C)."""
        raise NotImplementedError

    def mirror_behaviour(self) -> dict:
        """How the lobe varies with azimuth at the mirror direction (docs/method.md, "Diagnostics"); {} if n/a."""
        return {}

    # -- capabilities (module docstring) -----------------------------------------
    #: True when the kind carries a per-prediction σ (:meth:`predict_sigma`).
    has_sigma: ClassVar[bool] = False

    @property
    def has_table(self) -> bool:
        """True when :meth:`table_view` is the model's own (φ, γ) table, not a tabulation."""
        return False

    @property
    def sample_frame_warp(self) -> float:
        """Sample-frame azimuth of the warp, radians (0: the model is in the fabric frame)."""
        return 0.0

    def describe(self) -> str:
        """One line naming the model: kind, what it holds, channels."""
        return f"{self.kind} model, channels {', '.join(self.channels)}"

    def table_view(self, n_phi: int | None = None, n_gamma: int | None = None):
        """The tabulated lobe q(φ, γ) as a ``kes``-kind model (:func:`kesbrdf.models.table.tabulate`).

        Figures that read the table (Fig. 5), the table shaders and exports use it; the
        base class tabulates through :meth:`evaluate` so every kind has one.
        """
        key = (n_phi, n_gamma)
        cache = self.__dict__.setdefault("_table_views", {})
        if key not in cache:
            cache[key] = kind_class(TABLE_KIND).tabulate(self, n_phi, n_gamma)
        return cache[key]

    def predict_sigma(self, wi, wr):
        """``(f, σ, σ_ln f)`` at direction pairs (N, 3), or None: the kind carries no σ."""
        return None

    def render_plugin(self, mapping: str | None = None, extrapolation: str | None = None) -> tuple[str, dict]:
        """(Mitsuba plugin name, properties) drawing this model (module docstring).

        The base class: the ``kesbrdf`` table plugin on :meth:`table_view`, which takes
        the KES ``mapping`` and the ``extrapolation`` beyond the last γ.
        """
        props = {}
        if mapping is not None:
            props["mapping"] = mapping
        if extrapolation is not None:
            props["extrapolation"] = extrapolation
        return "kesbrdf", props

    def remember_fit(self, measurement, fitter: str, options: dict) -> None:
        """Keep what :meth:`refit` needs for this session: the measurement, the fitter
        and its options (not written to the model file)."""
        self.__dict__["_fit_memory"] = (measurement, fitter, dict(options))

    def refit_options(self) -> dict:
        """The options :meth:`refit` passes to the fitter: those of this session's fit,
        else the recorded ``parameters`` that are options of the fitter."""
        memory = self.__dict__.get("_fit_memory")
        if memory is not None:
            return dict(memory[2])
        fitter = fitter_class(self.fitter_name)
        return {k: v for k, v in self.parameters.items() if k in fitter.fit_options}

    @property
    def fitter_name(self) -> str:
        """The fitter that made this model (``parameters["fit"]`` when a fitting method
        other than the kind's own made it, e.g. ``scattered``)."""
        memory = self.__dict__.get("_fit_memory")
        if memory is not None:
            return memory[1]
        name = self.parameters.get("fit") if isinstance(self.parameters, dict) else None
        return name if isinstance(name, str) and name in FIT_MODULES else self.kind

    def refit(self, mask, measurement=None):
        """The same fit on the rows ``mask`` of ``measurement`` (default: the measurement
        this model was fitted to in this session); a one-line ModelError when there is none.
        """
        memory = self.__dict__.get("_fit_memory")
        m = measurement if measurement is not None else (memory[0] if memory else None)
        if m is None:
            raise ModelError(
                f"refit of a {self.kind!r} model: expected the measurement it was fitted to, got none "
                "(a model file holds no samples; pass the measurement)"
            )
        mask = np.asarray(mask)
        if mask.dtype == bool and mask.shape != (len(m),):
            raise ModelError(f"refit: expected a mask of {len(m)} rows, got shape {mask.shape}")
        sub = m.subset(mask)
        options = self.refit_options()
        model = fitter_class(self.fitter_name).fit_measurement(sub, **options)
        model.remember_fit(sub, self.fitter_name, options)
        return model

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

    @classmethod
    def auto_skip(cls, measurement) -> str | None:
        """Why ``kind="auto"`` should not consider this kind for ``measurement`` (or None)."""
        return None

    @classmethod
    def sparse_rows(cls, measurement) -> str | None:
        """Why ``kind="auto"`` should not let this kind take rows beyond a simpler kind's
        (or None): they are too sparse for it to use well, and a fit to them would predict
        worse than the simpler kind's fit to its subset (:func:`kesbrdf.fitting.choose_fitter`)."""
        return None

    def save(self, path):
        """Write the model file atomically (:mod:`kesbrdf.io.model_writer`)."""
        from kesbrdf.io.model_writer import save_model

        return save_model(path, self)


def check_fit_options(name: str, accepted, options) -> None:
    """A one-line :class:`ModelError` naming the options of ``options`` that the fitter
    ``name`` does not accept (``accepted``: its ``fit_options``).  Every fitter's
    ``fit_measurement`` calls it; :func:`kesbrdf.fit` checks first and also says which
    other kinds accept them."""
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ModelError(f"{name} fit: unknown option(s) {', '.join(unknown)}; expected {', '.join(accepted)}")


def register(cls: type) -> type:
    """Class decorator: add a :class:`ReflectanceModel` subclass to the registry.

    A kind is also the fitter of its own name.
    """
    if not cls.kind or not cls.mappings:
        raise RuntimeError(f"{cls.__name__}: a model kind needs 'kind' and 'mappings'")
    _REGISTRY[cls.kind] = cls
    _FITTERS.setdefault(cls.kind, cls)
    # a kind registered from elsewhere (a plug-in, a test) joins known_kinds() too
    KIND_MODULES.setdefault(cls.kind, cls.__module__)
    FIT_MODULES.setdefault(cls.kind, cls.__module__)
    return cls


def register_fitter(name: str):
    """Class decorator: register a fitter ``name`` (a class with ``kind`` — the kind it
    produces — ``fit_options``, and classmethods ``fit_measurement`` and ``usable_rows``)."""
    def deco(cls: type) -> type:
        for attr in ("kind", "fit_options", "fit_measurement", "usable_rows"):
            if not hasattr(cls, attr):
                raise RuntimeError(f"{cls.__name__}: a fitter needs {attr!r}")
        _FITTERS[name] = cls
        return cls

    return deco


def known_kinds() -> tuple[str, ...]:
    return tuple(KIND_MODULES)


def known_fitters() -> tuple[str, ...]:
    return tuple(FIT_MODULES)


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


def fitter_class(name) -> type:
    """The fitter ``name`` (a kind or a fitting method); one-line error naming the known ones."""
    if not isinstance(name, str) or name not in FIT_MODULES:
        raise ModelError(f"expected kind one of {', '.join(map(repr, ('auto',) + known_fitters()))}, got {name!r}")
    if name not in _FITTERS:
        importlib.import_module(FIT_MODULES[name])
    if name not in _FITTERS:
        raise RuntimeError(f"module {FIT_MODULES[name]} did not register fitter {name!r}")
    return _FITTERS[name]
