"""The export formats: name used by ``kesbrdf export --format`` -> module in this package.

Plain data, importing nothing, so the framework (:mod:`kesbrdf.export._framework`) and
the package front (:mod:`kesbrdf.export`) both read it without an import loop.  Adding a
format is one module and one line here (docs/architecture.md).
"""

from __future__ import annotations

__all__ = ["FORMATS"]

#: format name -> module (imported on use, so each format's dependencies stay optional)
FORMATS: dict[str, str] = {
    "rgl-bsdf": "rgl_bsdf",
    "rgl-bsdf-spectral": "rgl_bsdf_spectral",
    "mitsuba-scene": "mitsuba_scene",
    "gltf": "gltf",
    "glb": "glb",
    "mtlx": "mtlx",
    "usd": "usd",
    "brdf-explorer": "brdf_explorer",
}
