"""kesbrdf: anisotropic fabric BRDFs from the extended KES method (Takeda et al.).

Layers (DESIGN §6): io → measurement → kes → model → brdf → validation, with plotting,
render, viewer and cli on top.  Only numpy is needed for the core.

``kesbrdf.fit(measurement, kind="auto", **options) -> (model, report)`` is the one
fitting entry point (:mod:`kesbrdf.fitting`, docs/models.md).
"""

from kesbrdf._version import __version__

__all__ = ["__version__", "fit"]


def fit(measurement, kind: str = "auto", **options):
    """Fit a model of the best (or the given) kind; see :func:`kesbrdf.fitting.fit`."""
    from kesbrdf.fitting import fit as _fit

    return _fit(measurement, kind=kind, **options)
