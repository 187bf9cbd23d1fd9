"""glTF 2.0 binary export (format ``glb``): :func:`kesbrdf.export.gltf.export` with ``binary=True``."""

from __future__ import annotations

from kesbrdf.export._framework import ExportResult

__all__ = ["export"]


#: File endings ``kesbrdf export`` accepts for this format (checked before any work).
EXTENSIONS = (".glb",)
HELP = 'binary glTF 2.0 (.glb): the same fitted material and preview meshes'


def export(model, out, *, fit=None, fit_grid=None, error_grid=None) -> ExportResult:
    """Write a ``.glb`` (see :mod:`kesbrdf.export.gltf`)."""
    from kesbrdf.export.gltf import export as export_gltf

    return export_gltf(model, out, binary=True, fit=fit, fit_grid=fit_grid, error_grid=error_grid)
