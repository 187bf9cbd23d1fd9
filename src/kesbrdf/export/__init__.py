"""Exports: a kesbrdf model in the formats other tools read (``docs/exports.md``).

Each format is one module in this package; :data:`FORMATS` (:mod:`kesbrdf.export.registry`) maps the format name used by
``kesbrdf export --format`` to that module, which provides
``export(model, out_path, **options) -> ExportResult``.  One line per format.
:func:`export` (:mod:`kesbrdf.export._framework`) dispatches on it.
"""

from __future__ import annotations

from kesbrdf.export._framework import ExportResult, export, format_module, format_names
from kesbrdf.export.registry import FORMATS

__all__ = ["FORMATS", "ExportResult", "export", "format_module", "format_names"]
