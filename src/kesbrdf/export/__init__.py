"""Exports: a kesbrdf model in the formats other tools read (``docs/exports.md``).

Each format is one module in this package; :data:`FORMATS` maps the format name used by
``kesbrdf export --format`` to that module, which provides
``export(model, out_path, **options) -> ExportResult``.  One line per format.
"""

from __future__ import annotations

__all__ = ["FORMATS"]

#: format name -> module (imported on use, so each format's dependencies stay optional)
FORMATS: dict[str, str] = {
    "gltf": "kesbrdf.export.gltf",
    "glb": "kesbrdf.export.glb",
    "mtlx": "kesbrdf.export.mtlx",
    "usd": "kesbrdf.export.usd",
    "brdf-explorer": "kesbrdf.export.brdf_explorer",
}
