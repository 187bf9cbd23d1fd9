"""Lazy matplotlib access for the plotting package.

matplotlib is an optional dependency (extra ``plot``).  Figures are built with
:class:`matplotlib.figure.Figure` directly, never through ``pyplot``, so the library
neither needs nor changes a GUI backend: saving goes through the Agg/SVG/PDF canvases.
"""

from __future__ import annotations

__all__ = ["require_matplotlib", "new_figure"]


def require_matplotlib():
    """Import and return :mod:`matplotlib`, or raise ImportError naming the extra."""
    try:
        import matplotlib
        import matplotlib.figure  # noqa: F401
    except ImportError as exc:  # pragma: no cover - exercised only without matplotlib
        raise ImportError(
            "kesbrdf plotting needs matplotlib: install kesbrdf[plot]"
        ) from exc
    return matplotlib


def new_figure(figsize=(6.4, 4.8), dpi: int = 100):
    """A pyplot-free :class:`~matplotlib.figure.Figure` (works on any backend)."""
    require_matplotlib()
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, dpi=dpi, layout="constrained")
