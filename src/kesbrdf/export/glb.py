"""glTF 2.0 binary export (format ``glb``): :func:`kesbrdf.export.gltf.export` with ``binary=True``."""

from __future__ import annotations

__all__ = ["export"]


def export(model, out, **options) -> dict:
    """Write a ``.glb`` (see :mod:`kesbrdf.export.gltf`)."""
    from kesbrdf.export.gltf import export as export_gltf

    options["binary"] = True
    return export_gltf(model, out, **options)
