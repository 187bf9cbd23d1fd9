"""Reader of the CUReT BRDF database (scattered gonio data, real fabrics).

The Columbia-Utrecht Reflectance and Texture database (CUReT) measured 61 real
surfaces at the same 205 illumination/viewing configurations:

Dana, van Ginneken, Nayar, Koenderink, "Reflectance and texture of real-world
surfaces", ACM Transactions on Graphics 18(1), 1999.  Cite it when you use the data.

Two text files make up the BRDF part:

``table.txt``
    205 rows ``index theta_v phi_v theta_i phi_i``: the configurations, radians, in the
    *sample* frame (the azimuth zero is where the sample sat on the turntable, not
    the warp; :func:`kesbrdf.models.scattered.fit_scattered` estimates the warp azimuth).
``abrdf.dat``
    One row per sample: ``sample_number`` followed by 205 BRDF values (RGB-averaged,
    1/sr) in the order of ``table.txt``.  A few values are slightly negative (dark
    noise); they are kept and reported in :attr:`Measurement.notes`.

``theta_v, phi_v`` is the viewer (our ``theta_r, phi_r``); ``theta_i, phi_i`` the
light.  Checked on sample 15 (aluminium foil), whose maximum sits at the mirror
direction γ ≈ 0 of :func:`kesbrdf.models.brdf.to_phi_gamma`.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from kesbrdf.errors import FormatError, MeasurementError, where
from kesbrdf.io.files import read_regular
from kesbrdf.io.text import parse_number, split_lines
from kesbrdf.measure.measurement import Measurement

__all__ = ["read_curet", "FABRICS", "CITATION", "N_CONFIGURATIONS", "sample_name"]

#: Number of configurations of the CUReT BRDF table.
N_CONFIGURATIONS = 205

#: Fabric samples of CUReT by number (names from the database's sample list).
FABRICS = {
    1: "felt",
    2: "polyester",
    3: "terrycloth",
    7: "velvet",
    18: "rug_a",
    19: "rug_b",
    22: "lambswool",
    29: "polyester (zoomed)",
    42: "corduroy",
    44: "linen",
    46: "cotton",
}

CITATION = (
    "Dana, van Ginneken, Nayar, Koenderink, 'Reflectance and texture of real-world "
    "surfaces', ACM Transactions on Graphics 18(1):1-34, 1999 (CUReT database, Columbia University)"
)

#: Polar angles above this (radians) cannot be directions above the sample.
THETA_MAX = math.pi / 2 + 1e-9

#: Azimuths beyond one turn either way (radians) are refused as a units or format error.
PHI_MAX = 2 * math.pi + 1e-9


def sample_name(sample: int) -> str:
    """``"CUReT sample 42 (corduroy)"``; non-fabric samples get no name."""
    name = FABRICS.get(int(sample))
    return f"CUReT sample {int(sample)}" + (f" ({name})" if name else "")


def _decode_ascii(data: bytes, path: Path, what: str) -> str:
    try:
        return data.decode("ascii")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise FormatError(
            f"{where(path, line)}expected a plain-text (ASCII) CUReT {what} file, got the byte "
            f"0x{data[exc.start:exc.start + 1].hex()}"
        ) from None


def _numbers(fields, path: Path, lineno: int) -> list[float]:
    """Finite floats of bounded magnitude (:func:`kesbrdf.io.text.parse_number`)."""
    return [parse_number(f, f"{k + 1}", path, lineno) for k, f in enumerate(fields)]


def _numeric_rows(path: Path, n_fields: int, what: str):
    """(line numbers, float array (rows, n_fields)) of a whitespace-separated file."""
    data = read_regular(path)
    text = _decode_ascii(data, path, what)
    linenos, rows = [], []
    for lineno, raw in split_lines(text, path):
        fields = raw.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != n_fields:
            raise FormatError(
                f"{where(path, lineno)}expected {n_fields} fields in a CUReT {what} row, got {len(fields)}"
            )
        linenos.append(lineno)
        rows.append(_numbers(fields, path, lineno))
    if not rows:
        raise FormatError(f"{where(path)}expected CUReT {what} rows, got none")
    return np.array(linenos), np.array(rows), hashlib.sha256(data).hexdigest()


def read_table(table_path):
    """The configurations of ``table.txt``: (theta_v, phi_v, theta_i, phi_i) radians, sha256.

    Raises
    ------
    FormatError
        Wrong field count, non-numeric text, indices not 1…N in order, polar angles
        outside [0, π/2] (e.g. degrees instead of radians).
    """
    path = Path(table_path)
    linenos, rows, sha = _numeric_rows(path, 5, "table")
    index = rows[:, 0]
    expected = np.arange(1, len(rows) + 1)
    wrong = np.flatnonzero(index != expected)
    if wrong.size:
        k = wrong[0]
        raise FormatError(
            f"{where(path, int(linenos[k]))}expected configuration index {expected[k]}, got {index[k]:g}"
        )
    for col, name in ((1, "theta_v"), (3, "theta_i")):
        bad = (rows[:, col] < 0) | (rows[:, col] > THETA_MAX)
        if bad.any():
            k = int(np.argmax(bad))
            raise FormatError(
                f"{where(path, int(linenos[k]))}{name}: expected radians in [0, pi/2], got {rows[k, col]:g}"
            )
    for col, name in ((2, "phi_v"), (4, "phi_i")):
        bad = np.abs(rows[:, col]) > PHI_MAX
        if bad.any():
            k = int(np.argmax(bad))
            raise FormatError(
                f"{where(path, int(linenos[k]))}{name}: expected radians in [-2 pi, 2 pi], got {rows[k, col]:g}"
            )
    return rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4], sha


def read_curet(table_path, abrdf_path, sample) -> Measurement:
    """One CUReT sample as a :class:`~kesbrdf.measure.measurement.Measurement` (general geometry).

    Parameters
    ----------
    table_path, abrdf_path : path-like
        ``table.txt`` and ``abrdf.dat`` (module docstring).
    sample : int
        CUReT sample number, 1…61 (fabrics: :data:`FABRICS`).

    Returns
    -------
    Measurement
        205 rows, channel ``("value",)``, f_r in 1/sr, ``psi = None`` (general rows),
        angles in the sample frame (φ wrapped to [0, 2π)).  ``metadata`` names the
        sample and carries the citation; ``notes`` reports negative values, which are
        kept as measured.

    Raises
    ------
    FormatError
        Malformed files (with file:line), or a value count that does not match the table.
    MeasurementError
        The sample is not in the file, or appears twice.
    """
    table_path = Path(table_path)
    abrdf_path = Path(abrdf_path)
    theta_v, phi_v, theta_i, phi_i, table_sha = read_table(table_path)
    n = theta_v.size
    data = read_regular(abrdf_path)
    # the row length is checked against the table, so read rows of any length first
    text = _decode_ascii(data, abrdf_path, "abrdf")
    found = None
    seen = []
    for lineno, raw in split_lines(text, abrdf_path):
        fields = raw.split()
        if not fields or fields[0].startswith("#"):
            continue
        first = parse_number(fields[0], "1 (sample number)", abrdf_path, lineno)
        if first != int(first):
            raise FormatError(f"{where(abrdf_path, lineno)}expected an integer sample number, got {fields[0]!r}")
        number = int(first)
        seen.append(number)
        if number != int(sample):
            continue
        if found is not None:
            raise MeasurementError(
                f"{where(abrdf_path, lineno)}sample {number} appears twice (first at line {found[0]})"
            )
        if len(fields) != n + 1:
            raise FormatError(
                f"{where(abrdf_path, lineno)}expected 1 + {n} fields (sample number and one value per "
                f"configuration of {table_path.name}), got {len(fields)}"
            )
        values = np.array(
            [parse_number(f, f"{k + 2} (configuration {k + 1})", abrdf_path, lineno) for k, f in enumerate(fields[1:])]
        )
        found = (lineno, values)
    if found is None:
        got = f"{min(seen)}..{max(seen)}" if seen else "none"
        raise MeasurementError(f"{where(abrdf_path)}expected a row for sample {sample}, got samples {got}")
    lineno, values = found
    notes = []
    negative = values < 0
    if negative.any():
        notes.append(
            f"{int(negative.sum())} negative value(s) (dark noise), smallest {values.min():g}, first at "
            f"configuration {int(np.argmax(negative)) + 1} ({abrdf_path.name}:{lineno}); kept as measured"
        )
    name = FABRICS.get(int(sample))
    metadata = {
        "sample": sample_name(sample),
        "curet_sample": str(int(sample)),
        "material": name or "",
        "instrument": "CUReT gonioreflectometer (Columbia-Utrecht), robot arm, 205 configurations",
        "quantity": "brdf",
        "simulated": "false",
        "frame": "sample frame: azimuth zero is the turntable position, not the warp",
        "channels_unit": "1/sr, RGB-averaged",
        "citation": CITATION,
        "table_sha256": table_sha,
    }
    return Measurement(
        theta_i=theta_i,
        phi_i=np.mod(phi_i, 2 * np.pi),
        theta_r=theta_v,
        phi_r=np.mod(phi_v, 2 * np.pi),
        values=values[:, None],
        channels=("value",),
        psi=None,
        metadata=metadata,
        source=str(abrdf_path),
        sha256=hashlib.sha256(data).hexdigest(),
        notes=notes,
    )
