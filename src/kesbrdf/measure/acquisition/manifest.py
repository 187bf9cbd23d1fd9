"""The acquisition manifest: one camera frame per row.

Format, version 1::

    # kesbrdf-manifest: 1
    # sample: virtual black satin
    # white_reflectance: 0.99
    # response: linear
    file,kind,psi_deg,theta_i_deg,theta_r_deg,exposure_s,roi
    dark_0.004.tif,dark,,,,0.004,
    white_87_03.tif,white,,87,3,0.512,"4,4,28,28"
    s000_87_03.tif,sample,0,87,3,4.096,"4,4,28,28"

Header lines ``# key: value`` before the column row:

``white_reflectance`` (required when the manifest has white frames)
    Reflectance factor R of the Lambertian white reference, in (0, 1]; its BRDF is R/π.
``response``
    ``linear`` (default) or ``srgb``: how the stored code values encode the signal.
``saturation_level``
    Raw code value at or above which a pixel counts as clipped (default: the largest
    code of the bit depth, 255 or 65535; float frames: none unless given).
``sample``, ``instrument``, ``simulated``, ``generator``
    Copied into the measurement file's header.  Other keys are kept as metadata.

Columns: ``file`` (relative to the manifest's folder), ``kind`` (``sample``, ``white``
or ``dark``), ``exposure_s`` (> 0), and the geometry in degrees: ``psi_deg``,
``theta_i_deg``, ``theta_r_deg`` (in-plane, docs/method.md, "Conventions") and optionally ``phi_i_deg``,
``phi_r_deg`` (a general geometry; then ``psi_deg`` may be empty).  Sample rows need a
geometry, white rows need ``theta_i_deg`` and ``theta_r_deg`` (a Lambertian white is
isotropic, so ψ is ignored), dark rows need none.  ``roi`` is ``x0,y0,x1,y1`` in pixels,
x1 and y1 exclusive (Python slices ``[y0:y1, x0:x1]``); empty means the whole frame.
Separators ``,``, ``;`` or spaces are accepted inside the (quoted) field.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from kesbrdf._atomic import write_text
from kesbrdf.measure.acquisition.sensor import RESPONSES
from kesbrdf.errors import FormatError, validate_choice, where
from kesbrdf.io.files import read_regular
from kesbrdf.io.text import csv_fields, decode_text, parse_number, split_lines

__all__ = [
    "Manifest",
    "ManifestRow",
    "read_manifest",
    "parse_manifest",
    "format_manifest",
    "write_manifest",
    "KINDS",
    "COLUMNS",
]

FORMAT_VERSION = 1
KINDS = ("sample", "white", "dark")
#: Every column a manifest may have, in the order the writer uses.
COLUMNS = (
    "file",
    "kind",
    "psi_deg",
    "theta_i_deg",
    "theta_r_deg",
    "phi_i_deg",
    "phi_r_deg",
    "exposure_s",
    "roi",
)
REQUIRED_COLUMNS = ("file", "kind", "exposure_s")
ANGLE_COLUMNS = ("psi_deg", "theta_i_deg", "theta_r_deg", "phi_i_deg", "phi_r_deg")
#: Two sample rows closer than this in every angle have the same geometry (degrees).
SAME_GEOMETRY_DEG = 1e-3


@dataclass
class ManifestRow:
    """One frame of a manifest.  Angles in degrees (file edge); NaN where empty."""

    line: int
    file: str
    path: Path
    kind: str
    psi_deg: float
    theta_i_deg: float
    theta_r_deg: float
    phi_i_deg: float
    phi_r_deg: float
    exposure_s: float
    roi: tuple[int, int, int, int] | None

    @property
    def is_general(self) -> bool:
        """True when the row gives both azimuths (a general, not in-plane, geometry)."""
        return math.isfinite(self.phi_i_deg) and math.isfinite(self.phi_r_deg)


@dataclass
class Manifest:
    """A parsed manifest: header metadata and rows."""

    path: Path
    header: dict = field(default_factory=dict)
    rows: list = field(default_factory=list)

    @property
    def white_reflectance(self) -> float | None:
        value = self.header.get("white_reflectance")
        return None if value is None else float(value)

    @property
    def response(self) -> str:
        return self.header.get("response", "linear")

    @property
    def saturation_level(self) -> float | None:
        value = self.header.get("saturation_level")
        return None if value is None else float(value)

    def of_kind(self, kind: str) -> list:
        return [row for row in self.rows if row.kind == kind]


def read_manifest(path) -> Manifest:
    """Read and validate a manifest; errors name ``file:line``.

    Raises
    ------
    FileNotFoundError
        The manifest itself does not exist.
    FormatError
        Any format problem (see the module docstring).
    """
    path = Path(path)
    return parse_manifest(decode_text(read_regular(path), path), path)


def _parse_float(text: str, column: str, path, line: int) -> float:
    """A finite number, or NaN for an empty field."""
    return parse_number(text, column, path, line, empty=math.nan)


def _parse_roi(text: str, path, line: int):
    text = text.strip()
    if not text:
        return None
    parts = [p for p in re.split(r"[,;\s]+", text) if p]
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        numbers = []
    if len(numbers) != 4:
        raise FormatError(f"{where(path, line)}column roi: expected four integers x0,y0,x1,y1, got {text!r}")
    x0, y0, x1, y1 = numbers
    if min(numbers) < 0:
        raise FormatError(f"{where(path, line)}column roi: expected pixel coordinates >= 0, got {text!r}")
    if not (x1 > x0 and y1 > y0):
        raise FormatError(
            f"{where(path, line)}column roi: expected x1 > x0 and y1 > y0 (x1, y1 exclusive), got {text!r}"
        )
    return (x0, y0, x1, y1)


def _parse_header(key: str, value: str, path, line: int):
    if key == "white_reflectance":
        r = _parse_float(value, "white_reflectance", path, line)
        if not (0 < r <= 1):
            raise FormatError(f"{where(path, line)}white_reflectance: expected a reflectance factor in (0, 1], got {value!r}")
        return r
    if key == "response":
        return validate_choice("response", value.strip().lower(), RESPONSES, path, line, FormatError)
    if key == "saturation_level":
        level = _parse_float(value, "saturation_level", path, line)
        if not level > 0:
            raise FormatError(f"{where(path, line)}saturation_level: expected a positive code value, got {value!r}")
        return level
    if key == "kesbrdf-manifest":
        if value.strip() != str(FORMAT_VERSION):
            raise FormatError(f"{where(path, line)}expected manifest format version {FORMAT_VERSION}, got {value.strip()!r}")
        return FORMAT_VERSION
    return value.strip()


def parse_manifest(text: str, path="<string>") -> Manifest:
    """Parse manifest text; relative file names resolve against ``path``'s folder."""
    path = Path(path)
    base = path.parent
    header: dict = {}
    columns = None
    rows: list[ManifestRow] = []
    for lineno, raw in split_lines(text, path):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if columns is not None:
                continue  # comments after the header row are ignored
            body = stripped[1:].strip()
            if ":" in body:
                key, value = body.split(":", 1)
                key = key.strip()
                header[key] = _parse_header(key, value, path, lineno)
            continue
        cells = csv_fields(raw, path, lineno)
        if columns is None:
            columns = [c.strip() for c in cells]
            unknown = [c for c in columns if c not in COLUMNS]
            if unknown:
                raise FormatError(
                    f"{where(path, lineno)}unknown column {unknown[0]!r}; expected columns among {', '.join(COLUMNS)}"
                )
            missing = [c for c in REQUIRED_COLUMNS if c not in columns]
            if missing:
                raise FormatError(f"{where(path, lineno)}missing column {missing[0]!r}; expected at least {', '.join(REQUIRED_COLUMNS)}")
            if len(set(columns)) != len(columns):
                raise FormatError(f"{where(path, lineno)}duplicate column names in {', '.join(columns)}")
            continue
        if len(cells) != len(columns):
            raise FormatError(f"{where(path, lineno)}expected {len(columns)} fields, got {len(cells)}")
        record = dict(zip(columns, cells))
        rows.append(_parse_row(record, path, base, lineno))
    if columns is None:
        raise FormatError(f"{where(path)}expected a column row ({', '.join(REQUIRED_COLUMNS)}, ...), got none")
    if not rows:
        raise FormatError(f"{where(path)}expected at least one frame row, got none")
    if any(r.kind == "white" for r in rows) and "white_reflectance" not in header:
        raise FormatError(
            f"{where(path)}missing header line '# white_reflectance: R' (the white reference's reflectance factor)"
        )
    _check_duplicates(rows, path)
    return Manifest(path=path, header=header, rows=rows)


def _parse_row(record: dict, path, base: Path, line: int) -> ManifestRow:
    file = record["file"].strip()
    if not file:
        raise FormatError(f"{where(path, line)}column file: expected a file name, got an empty field")
    if any(ord(ch) < 32 for ch in file):
        raise FormatError(f"{where(path, line)}column file: expected a file name, got control characters in {file!r}")
    kind = validate_choice("column kind", record["kind"].strip().lower(), KINDS, path, line, FormatError)
    angles = {c: _parse_float(record.get(c, ""), c, path, line) for c in ANGLE_COLUMNS}
    for c in ("phi_i_deg", "phi_r_deg"):
        if math.isfinite(angles[c]) and not -360 <= angles[c] <= 360:
            raise FormatError(f"{where(path, line)}column {c}: expected degrees in [-360, 360], got {angles[c]:g}")
    exposure = _parse_float(record["exposure_s"], "exposure_s", path, line)
    if not exposure > 0:
        raise FormatError(f"{where(path, line)}column exposure_s: expected a positive time in seconds, got {record['exposure_s']!r}")
    roi = _parse_roi(record.get("roi", ""), path, line)
    if kind in ("sample", "white"):
        for c in ("theta_i_deg", "theta_r_deg"):
            if not math.isfinite(angles[c]):
                raise FormatError(f"{where(path, line)}column {c}: expected an angle for a {kind} frame, got an empty field")
            limit_ok = 0 <= angles[c] < 90 if c == "theta_i_deg" else 0 <= angles[c] <= 90
            if not limit_ok:
                bound = "[0, 90)" if c == "theta_i_deg" else "[0, 90]"
                raise FormatError(f"{where(path, line)}column {c}: expected degrees in {bound}, got {angles[c]:g}")
    if kind == "sample":
        general = math.isfinite(angles["phi_i_deg"]) and math.isfinite(angles["phi_r_deg"])
        if not general and not math.isfinite(angles["psi_deg"]):
            raise FormatError(
                f"{where(path, line)}sample frame: expected psi_deg (in-plane) or phi_i_deg and phi_r_deg, got neither"
            )
    if math.isfinite(angles["psi_deg"]) and not (0 <= angles["psi_deg"] < 180):
        raise FormatError(f"{where(path, line)}column psi_deg: expected degrees in [0, 180), got {angles['psi_deg']:g}")
    for c in ("theta_i_deg", "theta_r_deg"):  # also on dark rows, where they are not used
        if math.isfinite(angles[c]) and not 0 <= angles[c] <= 90:
            raise FormatError(f"{where(path, line)}column {c}: expected degrees in [0, 90], got {angles[c]:g}")
    file_path = Path(file)
    if not file_path.is_absolute():
        file_path = base / file_path
    return ManifestRow(line=line, file=file, path=file_path, kind=kind, exposure_s=exposure, roi=roi, **angles)


def _geometry_key(row: ManifestRow) -> tuple:
    q = 1.0 / SAME_GEOMETRY_DEG
    return tuple(
        None if not math.isfinite(v) else round(v * q)
        for v in (row.psi_deg, row.theta_i_deg, row.theta_r_deg, row.phi_i_deg, row.phi_r_deg)
    )


def _check_duplicates(rows, path) -> None:
    seen: dict = {}
    for row in rows:
        if row.kind != "sample":
            continue
        key = _geometry_key(row)
        if key in seen:
            raise FormatError(
                f"{where(path, row.line)}{row.file}: duplicate sample geometry, already on line {seen[key]}"
            )
        seen[key] = row.line


def _fmt(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        if not math.isfinite(value):
            return ""
        r = round(value, 9)
        return str(int(r)) if r == int(r) else repr(r)
    if isinstance(value, (tuple, list)):
        return ",".join(str(int(v)) for v in value)
    return str(value)


def format_manifest(header: dict, rows: list[dict]) -> str:
    """Manifest text from header items and row dicts (keys among :data:`COLUMNS`)."""
    out = io.StringIO()
    out.write(f"# kesbrdf-manifest: {FORMAT_VERSION}\n")
    for key, value in header.items():
        if key == "kesbrdf-manifest":
            continue
        out.write(f"# {key}: {' '.join(str(value).split())}\n")
    columns = [c for c in COLUMNS if any(c in r for r in rows)]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(columns)
    for r in rows:
        writer.writerow([_fmt(r.get(c)) for c in columns])
    return out.getvalue()


def write_manifest(path, header: dict, rows: list[dict]) -> Path:
    """Write a manifest atomically (see :func:`format_manifest`)."""
    return write_text(path, format_manifest(header, rows))
