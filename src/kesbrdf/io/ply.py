"""Triangle meshes as binary little-endian PLY, the layout Mitsuba 3's ``ply`` shape reads.

Written layout (one element each, in this order)::

    element vertex N
    property float x / y / z        position [m]
    property float nx / ny / nz     unit vertex normal
    property float u / v            texture coordinates (u along the warp, see docs/drape.md)
    element face M
    property list uchar int vertex_indices     triangles

This is the package's one PLY reader and writer (the cloth simulation's frames, the
renderer's procedural meshes) and its one vertex-normal function.  Only numpy is
needed.  Writing is atomic (:mod:`kesbrdf._atomic`); the reader accepts
any binary little-endian PLY with scalar vertex properties and a triangle face list,
so it can read back what Mitsuba or this module wrote.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kesbrdf._atomic import atomic_path
from kesbrdf.errors import FormatError, where
from kesbrdf.io.files import read_regular

__all__ = ["PlyMesh", "write_ply", "read_ply", "vertex_normals"]

#: PLY scalar type names -> numpy little-endian dtypes.
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
    "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}


@dataclass(frozen=True)
class PlyMesh:
    """A triangle mesh read from or written to PLY.

    Attributes
    ----------
    vertices : (N, 3) float32, metres.
    faces : (M, 3) int32 vertex indices, counter-clockwise around the normal.
    normals : (N, 3) float32 unit normals, or None.
    uv : (N, 2) float32 texture coordinates, or None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None


def vertex_normals(vertices, faces, fallback=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Area-weighted unit vertex normals of a triangle mesh.

    Each face adds its (unnormalised) cross product ``(p1 - p0) × (p2 - p0)``, whose
    length is twice its area, to its three vertices; the sums are normalised.  A vertex
    in no face (or only in degenerate ones) gets ``fallback``.

    Parameters
    ----------
    vertices : (N, 3) array_like
    faces : (M, 3) array_like of int
    fallback : (3,) array_like
        Unit normal of vertices without a defined normal: the world's up axis, ``(0, 0, 1)``
        for the z-up cloth simulation (default), ``(0, 1, 0)`` for the y-up render scenes.

    Returns
    -------
    (N, 3) float32 unit vectors.

    >>> p = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    >>> vertex_normals(p, [[0, 1, 2]])[0].tolist()
    [0.0, 0.0, 1.0]
    """
    p = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    face_n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, f[:, k], face_n)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = length[:, 0] > 0
    n[ok] /= length[ok]
    n[~ok] = np.asarray(fallback, dtype=np.float64)
    return n.astype(np.float32)


def _vertex_dtype(with_normals: bool, with_uv: bool) -> np.dtype:
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if with_normals else []) + (["u", "v"] if with_uv else [])
    return np.dtype([(name, "<f4") for name in names])


def write_ply(path, vertices, faces, normals=None, uv=None, comment: str | None = None) -> Path:
    """Write a triangle mesh as binary little-endian PLY, atomically.

    Parameters
    ----------
    path : path-like
    vertices : (N, 3) array_like, metres.
    faces : (M, 3) array_like of int in [0, N).
    normals : (N, 3) array_like or None
        Written as ``nx ny nz`` when given.
    uv : (N, 2) array_like or None
        Written as ``u v`` when given.
    comment : str, optional
        One header comment line (no newlines).

    Returns
    -------
    Path of the written file.
    """
    p = np.asarray(vertices, dtype=np.float32)
    f = np.asarray(faces)
    if p.ndim != 2 or p.shape[1] != 3:
        raise FormatError(f"{where(path)}expected vertices of shape (N, 3), got {p.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise FormatError(f"{where(path)}expected triangle faces of shape (M, 3), got {f.shape}")
    if f.size and (f.min() < 0 or f.max() >= len(p)):
        raise FormatError(f"{where(path)}expected face indices in [0, {len(p) - 1}], got [{f.min()}, {f.max()}]")
    dtype = _vertex_dtype(normals is not None, uv is not None)
    rec = np.empty(len(p), dtype=dtype)
    rec["x"], rec["y"], rec["z"] = p[:, 0], p[:, 1], p[:, 2]
    if normals is not None:
        n = np.asarray(normals, dtype=np.float32).reshape(len(p), 3)
        rec["nx"], rec["ny"], rec["nz"] = n[:, 0], n[:, 1], n[:, 2]
    if uv is not None:
        t = np.asarray(uv, dtype=np.float32).reshape(len(p), 2)
        rec["u"], rec["v"] = t[:, 0], t[:, 1]
    face_rec = np.empty(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["i"] = f.astype(np.int32)
    header = ["ply", "format binary_little_endian 1.0"]
    if comment:
        header.append("comment " + " ".join(str(comment).split()))
    header.append(f"element vertex {len(p)}")
    header += [f"property float {name}" for name in dtype.names]
    header += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(("\n".join(header) + "\n").encode("ascii"))
            fh.write(rec.tobytes())
            fh.write(face_rec.tobytes())
    return Path(path)


def read_ply(path: str | os.PathLike) -> PlyMesh:
    """Read a binary little-endian triangle PLY (vertex x y z [nx ny nz] [u v], faces).

    Raises
    ------
    FormatError
        Not a PLY, not binary little-endian, a non-triangle face, or a truncated file;
        the message names the file and the header line.
    """
    path = Path(path)
    data = read_regular(path)
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise FormatError(f"{where(path, 1)}expected a PLY header ('ply' ... 'end_header'), got none")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    body = memoryview(data)[end + len(b"end_header\n"):]
    elements: list[list] = []  # [name, count, [(prop, dtype | (count_dtype, item_dtype))]]
    for lineno, line in enumerate(header, start=1):
        words = line.split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        if words[0] == "format":
            if words[1:2] != ["binary_little_endian"]:
                raise FormatError(f"{where(path, lineno)}expected format binary_little_endian, got {' '.join(words[1:])}")
        elif words[0] == "element":
            elements.append([words[1], int(words[2]), []])
        elif words[0] == "property" and elements:
            try:
                if words[1] == "list":
                    elements[-1][2].append((words[4], (_PLY_TYPES[words[2]], _PLY_TYPES[words[3]])))
                else:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            except (KeyError, IndexError):
                raise FormatError(f"{where(path, lineno)}expected a PLY property declaration, got {line!r}") from None
        else:
            raise FormatError(f"{where(path, lineno)}unexpected header line {line!r}")
    offset = 0
    vertex = None
    faces = None
    for name, count, props in elements:
        if any(isinstance(t, tuple) for _, t in props):
            if name != "face" or len(props) != 1:
                raise FormatError(f"{where(path)}expected only the face element to hold a list property, got {name!r}")
            count_t, item_t = props[0][1]
            rec_t = np.dtype([("n", count_t), ("i", item_t, (3,))])
            need = rec_t.itemsize * count
            if len(body) - offset < need:
                raise FormatError(f"{where(path)}truncated face data: expected {need} bytes, got {len(body) - offset}")
            rec = np.frombuffer(body, dtype=rec_t, count=count, offset=offset)
            if count and np.any(rec["n"] != 3):
                raise FormatError(f"{where(path)}expected triangles only, got a face with {int(rec['n'][rec['n'] != 3][0])} vertices")
            faces = rec["i"].astype(np.int32)
            offset += need
        else:
            rec_t = np.dtype([(p, t) for p, t in props])
            need = rec_t.itemsize * count
            if len(body) - offset < need:
                raise FormatError(f"{where(path)}truncated {name} data: expected {need} bytes, got {len(body) - offset}")
            rec = np.frombuffer(body, dtype=rec_t, count=count, offset=offset)
            offset += need
            if name == "vertex":
                vertex = rec
    if vertex is None or faces is None:
        raise FormatError(f"{where(path)}expected 'vertex' and 'face' elements, got {[e[0] for e in elements]}")
    names = vertex.dtype.names

    def stack(keys):
        return np.stack([vertex[k].astype(np.float32) for k in keys], axis=-1) if all(k in names for k in keys) else None

    return PlyMesh(
        vertices=stack(("x", "y", "z")),
        faces=faces,
        normals=stack(("nx", "ny", "nz")),
        uv=stack(("u", "v")),
    )
