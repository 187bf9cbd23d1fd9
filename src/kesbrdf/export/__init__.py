"""Exports: a kesbrdf model in the formats other tools read (``docs/exports.md``).

Each format is one module in this package; :data:`FORMATS` maps the format name used by
``kesbrdf export --format`` to that module, which provides
``export(model, out_path, **options) -> ExportResult``.  One line per format.
:func:`export` (:mod:`kesbrdf.export._framework`) dispatches on it.
"""

from __future__ import annotations

from kesbrdf.export._framework import ExportResult, export, format_module, format_names

__all__ = ["FORMATS", "ExportResult", "export", "format_module", "format_names"]

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
