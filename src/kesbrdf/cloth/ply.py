"""Binary PLY meshes for the cloth simulation: see :mod:`kesbrdf.io.ply` (the one PLY reader/writer).

Kept so that ``kesbrdf.cloth.ply`` imports keep working.
"""

from kesbrdf.io.ply import PlyMesh, read_ply, vertex_normals, write_ply

__all__ = ["PlyMesh", "write_ply", "read_ply", "vertex_normals"]
