"""kesbrdf: anisotropic fabric BRDFs from the extended KES method (Takeda et al.).

The paper's steps are folders: ``measure`` (acquire), ``models`` (interpolate and model)
and ``validate``; plotting, render, viewer, export, batch and cli sit on top
(docs/architecture.md).  Only numpy is needed for the core.

``kesbrdf.fit(measurement, kind="auto", **options) -> (model, report)`` is the one
fitting entry point (:mod:`kesbrdf.fitting`, docs/models.md).
"""

from kesbrdf._version import __version__

__all__ = ["__version__", "fit"]


def fit(measurement, kind: str = "auto", **options):
    """Fit a model of the best (or the given) kind; see :func:`kesbrdf.fitting.fit`."""
    from kesbrdf.fitting import fit as _fit

    return _fit(measurement, kind=kind, **options)
