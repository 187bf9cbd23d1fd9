"""The Mitsuba / RGL-EPFL *tensor file* container (the ``*.bsdf`` of Dupuy & Jakob 2018).

Layout (little-endian), as Mitsuba 3's ``TensorFile`` reads it::

    char[12]  "tensor_file\\0"
    u8, u8    format version 1, 0
    u32       number of fields
    per field: u16 name length, name bytes (no NUL), u16 ndim, u8 dtype code,
               u64 absolute data offset, u64 shape[ndim]
    data:     C-order arrays at their offsets (aligned to 8 bytes here)

dtype codes: 1 u8, 2 i8, 3 u16, 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f16, 10 f32, 11 f64.
The field order is free and readers ignore fields they do not know.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from kesbrdf.errors import ExportError, FormatError, where
from kesbrdf.io.files import read_regular

__all__ = ["read_tensor_file", "write_tensor_file", "tensor_file_bytes", "DTYPE_CODES", "MAGIC"]

MAGIC = b"tensor_file\0"
#: numpy dtype (little-endian) -> tensor-file code
DTYPE_CODES = {
    np.dtype("u1"): 1, np.dtype("i1"): 2, np.dtype("<u2"): 3, np.dtype("<i2"): 4,
    np.dtype("<u4"): 5, np.dtype("<i4"): 6, np.dtype("<u8"): 7, np.dtype("<i8"): 8,
    np.dtype("<f2"): 9, np.dtype("<f4"): 10, np.dtype("<f8"): 11,
}
_ALIGN = 8


def tensor_file_bytes(fields: dict) -> bytes:
    """The bytes of a tensor file holding ``fields`` (name -> array, in that order).

    Arrays keep their dtype (converted to little-endian); a ``str`` or ``bytes`` value is
    stored as a u8 array (how the RGL files store ``description``).  Float arrays must be
    finite (an ExportError names the field otherwise: no renderer reads NaN or inf
    tables faithfully).
    """
    arrays = []
    for name, value in fields.items():
        if isinstance(value, str):
            value = value.encode("utf-8")
        if isinstance(value, (bytes, bytearray)):
            value = np.frombuffer(bytes(value), np.uint8)
        a = np.asarray(value)  # not ascontiguousarray: it turns 0-d arrays into 1-d
        a = a if a.flags.c_contiguous else a.copy(order="C")
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
        if dt not in DTYPE_CODES:
            raise FormatError(f"tensor file field {name!r}: expected a numeric dtype, got {a.dtype}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ExportError(f"tensor file field {name!r}: expected finite values, got "
                              f"{int(np.count_nonzero(~np.isfinite(a)))} NaN or inf (beyond the {a.dtype} range?)")
        arrays.append((name.encode("ascii"), a.astype(dt, copy=False)))
    header = len(MAGIC) + 2 + 4 + sum(2 + len(n) + 2 + 1 + 8 + 8 * a.ndim for n, a in arrays)
    offset = -(-header // _ALIGN) * _ALIGN
    head = [MAGIC, struct.pack("<BBI", 1, 0, len(arrays))]
    blobs = []
    for name, a in arrays:
        head.append(struct.pack("<H", len(name)) + name + struct.pack("<HBQ", a.ndim, DTYPE_CODES[a.dtype], offset))
        head.append(struct.pack(f"<{a.ndim}Q", *a.shape))
        data = a.tobytes()
        pad = -len(data) % _ALIGN
        blobs.append(data + b"\0" * pad)
        offset += len(data) + pad
    out = b"".join(head)
    out += b"\0" * (-len(out) % _ALIGN)
    return out + b"".join(blobs)


def write_tensor_file(path, fields: dict) -> Path:
    """Write ``fields`` as a tensor file at ``path``, atomically."""
    from kesbrdf._atomic import write_bytes

    return write_bytes(path, tensor_file_bytes(fields))


#: Tensor-file dtype codes (Mitsuba ``Struct::Type``) to numpy.
_DTYPES = {1: "u1", 2: "i1", 3: "u2", 4: "i2", 5: "u4", 6: "i4", 7: "u8", 8: "i8", 9: "f2", 10: "f4", 11: "f8"}


def read_tensor_file(path) -> dict:
    """Read a Mitsuba tensor file (the RGL database's ``*.bsdf``) into numpy arrays.

    Used to validate a file and read its description before Mitsuba loads it.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        Field name -> ndarray (little-endian, read-only views of the file bytes).

    Raises
    ------
    FormatError
        Not a tensor file, or truncated.
    """
    path = Path(path)
    try:
        data = read_regular(path)
    except OSError as exc:
        raise FormatError(f"{where(path)}expected a readable RGL tensor file (*.bsdf), got {exc.strerror}") from exc
    if data[: len(MAGIC)] != MAGIC:
        raise FormatError(f"{where(path)}expected a Mitsuba tensor file starting with 'tensor_file', got {data[:12]!r}")
    fields = {}
    try:
        pos = len(MAGIC) + 2  # magic, format version (2 bytes)
        (count,) = struct.unpack_from("<I", data, pos)
        pos += 4
        for _ in range(count):
            (name_len,) = struct.unpack_from("<H", data, pos)
            pos += 2
            name = data[pos : pos + name_len].decode("ascii")
            pos += name_len
            ndim, code, offset = struct.unpack_from("<HBQ", data, pos)
            pos += 11
            shape = struct.unpack_from("<" + "Q" * ndim, data, pos)
            pos += 8 * ndim
            dtype = np.dtype(_DTYPES[code]).newbyteorder("<")
            size = int(np.prod(shape)) if ndim else 1
            if offset + size * dtype.itemsize > len(data):
                raise ValueError(f"field {name!r} runs past the end of the file")
            fields[name] = np.frombuffer(data, dtype, size, offset).reshape(shape)
    except (struct.error, KeyError, ValueError, UnicodeDecodeError) as exc:
        raise FormatError(f"{where(path)}expected a well-formed tensor file, got a corrupt header ({exc})") from exc
    return fields
