"""Format ``rgl-bsdf-spectral``: the spectral RGL tensor file for pbrt-v4 (:mod:`kesbrdf.export.rgl_bsdf`)."""

from kesbrdf.export.rgl_bsdf import EXTENSIONS, export_spectral as export

__all__ = ["export", "EXTENSIONS", "HELP"]

HELP = "spectral RGL tensor file for pbrt-v4 MeasuredBxDF (and Mitsuba 3 spectral variants)"
