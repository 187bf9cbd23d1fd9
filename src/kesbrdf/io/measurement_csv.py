"""Reader and writer of the measurement CSV format (``docs/formats.md``).

Validation happens here, at the edge: every problem is reported as one line naming
the file and the line, and the library never sees a malformed measurement.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import re
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_text
from kesbrdf.errors import FormatError, MeasurementError, validate_choice, where
from kesbrdf.io.files import read_regular
from kesbrdf.io.text import csv_fields, decode_text, parse_number, split_lines
from kesbrdf.measure.measurement import Measurement

__all__ = ["read_measurement", "write_measurement", "QUANTITIES", "FORMAT_VERSION"]

FORMAT_VERSION = 1

#: Quantities a file may hold and their conversion to f_r (1/sr).
QUANTITIES = ("brdf", "reflectance_factor", "radiance_ratio")

IN_PLANE_COLUMNS = ("psi_deg", "theta_i_deg", "theta_r_deg")
GENERAL_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_r_deg", "phi_r_deg")
GEOMETRY_COLUMNS = set(IN_PLANE_COLUMNS) | set(GENERAL_COLUMNS)
TEXT_COLUMNS = ("file", "file_sha256", "flag")
FLAGS = ("ok", "lower_bound", "flagged")

#: Channel column names: ``value``; colour ``R,G,B`` (or ``X,Y,Z``, ``L``);
#: spectral bands ``nm550`` / ``550nm`` / ``band_<name>``.
CHANNEL_PATTERN = re.compile(r"^(value|[RGBXYZL]|nm\d+(\.\d+)?|\d+(\.\d+)?nm|band_\w+)$")

#: Two rows with the same geometry whose values differ by more than this relative
#: amount (or by more than 3 combined standard deviations when uncertainties are
#: given) conflict.
DUPLICATE_RTOL = 1e-6


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_measurement(path) -> Measurement:
    """Read a measurement CSV and convert its values to f_r in 1/sr.

    Raises
    ------
    FormatError
        Malformed file: missing/unknown columns, non-numeric or non-finite values,
        angles out of range or in radians, unknown quantity.
    MeasurementError
        Duplicate geometries with conflicting values.
    """
    path = Path(path)
    data = read_regular(path)
    return parse_measurement(decode_text(data, path), source=str(path), sha256=_sha256(data))


def parse_measurement(text: str, source: str = "<string>", sha256: str | None = None) -> Measurement:
    """Parse measurement CSV ``text``; ``source`` names it in error messages."""
    metadata: dict[str, str] = {}
    metadata_lines: dict[str, int] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for lineno, raw in split_lines(text, source):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            if header is None:
                body = line[1:].strip()
                if ":" in body:
                    key, value = body.split(":", 1)
                    metadata[key.strip().lower()] = value.strip()
                    metadata_lines[key.strip().lower()] = lineno
            continue
        fields = csv_fields(line, source, lineno)
        if header is None:
            header = [f.strip() for f in fields]
            header_line = lineno
        else:
            rows.append((lineno, [f.strip() for f in fields]))
    if header is None:
        raise FormatError(f"{where(source)}expected a header row of column names, got no data")

    version = metadata.get("kesbrdf-measurement", str(FORMAT_VERSION))
    if version != str(FORMAT_VERSION):
        raise FormatError(
            f"{where(source, metadata_lines.get('kesbrdf-measurement'))}expected measurement format version {FORMAT_VERSION}, got {version!r}"
        )
    quantity = validate_choice("quantity", metadata.get("quantity", "brdf").lower(), QUANTITIES, source,
                               metadata_lines.get("quantity"), FormatError)

    columns = _classify_columns(header, source, header_line)
    geometry, channels, unc_cols, text_cols = columns
    index = {name: k for k, name in enumerate(header)}
    if not rows:
        raise FormatError(f"{where(source, header_line)}expected data rows after the header, got none")

    n = len(rows)
    numeric_names = list(geometry) + list(channels) + [f"{c}_unc" for c in unc_cols]
    numeric = {name: np.empty(n) for name in numeric_names}
    text_values: dict[str, list[str]] = {name: [] for name in text_cols}
    for r, (lineno, fields) in enumerate(rows):
        if len(fields) != len(header):
            raise FormatError(
                f"{where(source, lineno)}expected {len(header)} fields as in the header, got {len(fields)}"
            )
        for name in numeric_names:
            numeric[name][r] = parse_number(fields[index[name]], name, source, lineno)
        for name in text_cols:
            text_values[name].append(fields[index[name]])
    linenos = np.array([ln for ln, _ in rows])

    _check_angles(numeric, geometry, linenos, source)
    if "flag" in text_values:
        for k, flag in enumerate(text_values["flag"]):
            validate_choice("column flag", flag, FLAGS, source, int(linenos[k]), FormatError)

    values = np.stack([numeric[c] for c in channels], axis=-1)
    uncertainty = None
    if unc_cols:
        uncertainty = np.stack(
            [numeric[f"{c}_unc"] if c in unc_cols else np.zeros(n) for c in channels], axis=-1
        )
        bad = np.argwhere(uncertainty < 0)
        if bad.size:
            r, c = bad[0]
            raise FormatError(
                f"{where(source, int(linenos[r]))}column {channels[c]}_unc: expected a "
                f"non-negative uncertainty, got {uncertainty[r, c]:g}"
            )

    theta_i = np.radians(numeric["theta_i_deg"])
    theta_r = np.radians(numeric["theta_r_deg"])
    if "psi_deg" in geometry:
        psi = np.radians(numeric["psi_deg"])
        phi_i = np.mod(psi + np.pi, 2 * np.pi)
        phi_r = psi.copy()
    else:
        phi_i = np.mod(np.radians(numeric["phi_i_deg"]), 2 * np.pi)
        phi_r = np.mod(np.radians(numeric["phi_r_deg"]), 2 * np.pi)
        psi = in_plane_psi(phi_i, phi_r)

    if quantity == "radiance_ratio":
        grazing = numeric["theta_i_deg"] >= 90.0
        if grazing.any():
            k = int(np.argmax(grazing))
            raise FormatError(
                f"{where(source, int(linenos[k]))}column theta_i_deg: expected degrees in [0, 90) for quantity "
                f"radiance_ratio (f_r = ratio / cos theta_i is unbounded at 90), got {numeric['theta_i_deg'][k]:g}"
            )
    scale = _to_brdf_scale(quantity, theta_i)
    with np.errstate(over="ignore", invalid="ignore"):
        values = values * scale[:, None]
        if uncertainty is not None:
            uncertainty = uncertainty * scale[:, None]
    # finite in the file is not enough: 1/cos(theta_i) of radiance_ratio grows without bound
    for array, what in ((values, ""), (uncertainty, "_unc")):
        if array is None:
            continue
        bad = np.argwhere(~np.isfinite(array))
        if bad.size:
            r, c = bad[0]
            raise FormatError(
                f"{where(source, int(linenos[r]))}column {channels[c]}{what}: expected a value that stays "
                f"finite as f_r in 1/sr, got an overflow converting {quantity} at theta_i_deg "
                f"{numeric['theta_i_deg'][r]:g}"
            )

    _check_duplicates(psi, theta_i, phi_i, theta_r, phi_r, values, uncertainty, linenos, source)

    notes = []
    negative = values < 0
    if negative.any():
        first = int(linenos[np.argwhere(negative)[0][0]])
        notes.append(
            f"{negative.sum()} negative value(s) (dark noise?), first at line {first}; "
            "they are kept and floored by the KES fit"
        )
    metadata["quantity"] = quantity
    return Measurement(
        theta_i=theta_i,
        phi_i=phi_i,
        theta_r=theta_r,
        phi_r=phi_r,
        values=values,
        channels=tuple(channels),
        uncertainty=uncertainty,
        psi=psi,
        metadata=metadata,
        provenance=text_values,
        source=source,
        sha256=sha256,
        notes=notes,
    )


#: How far (degrees) φ_i may be from φ_r + 180° for a general-form row to count as in the
#: plane of incidence: far above the writer's 1e-9° rounding, far below any gonio step.
IN_PLANE_TOL_DEG = 1e-4


def in_plane_psi(phi_i, phi_r):
    """ψ of the general-form rows that lie in the plane of incidence, NaN elsewhere; None
    when no row does.

    A row is in the plane when the light is opposite the viewer in azimuth (φ_i = φ_r +
    180°, within :data:`IN_PLANE_TOL_DEG`) and φ_r is in [0, 180°): it is then the
    in-plane sample ψ = φ_r, exactly what the ``psi_deg`` columns mean.  Rows at φ_r in
    [180°, 360°) stay general (the in-plane form would swap θ_i and θ_r).  So a
    measurement reads the same whichever column set wrote it: the paper protocol plus a
    few out-of-plane pairs is still the paper's incidence lines plus extras
    (docs/formats.md).
    """
    gap = np.abs(np.mod(phi_i - phi_r, 2 * np.pi) - np.pi)  # |φ_i − φ_r − 180°|, wrapped
    ok = (gap < np.radians(IN_PLANE_TOL_DEG)) & (phi_r < np.pi - np.radians(IN_PLANE_TOL_DEG))
    if not ok.any():
        return None
    return np.where(ok, phi_r, np.nan)


def _classify_columns(header, source, line):
    seen = set()
    for name in header:
        if name in seen:
            raise FormatError(f"{where(source, line)}column {name!r} appears twice")
        seen.add(name)
    if "psi_deg" in seen:
        geometry = IN_PLANE_COLUMNS
        extra = {"phi_i_deg", "phi_r_deg"} & seen
        if extra:
            raise FormatError(
                f"{where(source, line)}expected either psi_deg (in-plane) or phi_i_deg/phi_r_deg "
                f"(general) geometry, got both: {', '.join(sorted(extra | {'psi_deg'}))}"
            )
    else:
        geometry = GENERAL_COLUMNS
    missing = [c for c in geometry if c not in seen]
    if missing:
        raise FormatError(
            f"{where(source, line)}missing column(s) {', '.join(missing)}; expected "
            f"{','.join(IN_PLANE_COLUMNS)} (in-plane) or {','.join(GENERAL_COLUMNS)} (general)"
        )
    channels, uncs, texts = [], [], []
    for name in header:
        if name in GEOMETRY_COLUMNS:
            continue
        if name in TEXT_COLUMNS:
            texts.append(name)
        elif name.endswith("_unc") and CHANNEL_PATTERN.match(name[:-4]):
            uncs.append(name[:-4])
        elif CHANNEL_PATTERN.match(name):
            channels.append(name)
        else:
            raise FormatError(
                f"{where(source, line)}unknown column {name!r}; expected geometry columns, "
                "value or channel columns (R,G,B / nm550 / band_x), <channel>_unc, file, file_sha256, flag"
            )
    if not channels:
        raise FormatError(
            f"{where(source, line)}missing value column; expected 'value' or channel columns such as R,G,B"
        )
    if "value" in channels and len(channels) > 1:
        raise FormatError(
            f"{where(source, line)}expected either 'value' or channel columns, got both: {', '.join(channels)}"
        )
    for c in uncs:
        if c not in channels:
            raise FormatError(f"{where(source, line)}column {c}_unc has no channel column {c!r}")
    return geometry, channels, uncs, texts


def _check_angles(numeric, geometry, linenos, source):
    ranges = {
        "psi_deg": (0.0, 180.0, "[0, 180); a sample at psi+180 is the same as psi with theta_i and theta_r swapped"),
        "theta_i_deg": (0.0, 90.0, "[0, 90]"),
        "theta_r_deg": (0.0, 90.0, "[0, 90]"),
        "phi_i_deg": (-360.0, 360.0, "[-360, 360]"),
        "phi_r_deg": (-360.0, 360.0, "[-360, 360]"),
    }
    for name in geometry:
        lo, hi, text = ranges[name]
        col = numeric[name]
        bad = (col < lo) | (col > hi) | ((name == "psi_deg") & (col >= 180.0))
        if bad.any():
            k = int(np.argmax(bad))
            raise FormatError(
                f"{where(source, int(linenos[k]))}column {name}: expected degrees in {text}, got {col[k]:g}"
            )
    thetas = np.concatenate([numeric["theta_i_deg"], numeric["theta_r_deg"]])
    if len(linenos) > 3 and thetas.max() <= math.pi / 2 + 1e-9 and thetas.max() > 0:
        raise FormatError(
            f"{where(source, int(linenos[0]))}theta columns look like radians (all values <= pi/2, "
            f"largest {thetas.max():.4g}); expected degrees in *_deg columns"
        )


def _check_duplicates(psi, theta_i, phi_i, theta_r, phi_r, values, unc, linenos, source):
    key = np.column_stack([theta_i, np.mod(phi_i, 2 * np.pi), theta_r, np.mod(phi_r, 2 * np.pi)])
    key = np.round(key, 9)
    order = np.lexsort(key.T[::-1])
    sk = key[order]
    same = np.all(sk[1:] == sk[:-1], axis=1)
    for j in np.flatnonzero(same):
        a, b = order[j], order[j + 1]
        diff = np.abs(values[a] - values[b])
        if unc is not None:
            limit = 3 * np.hypot(unc[a], unc[b])
        else:
            limit = DUPLICATE_RTOL * np.maximum(np.abs(values[a]), np.abs(values[b]))
        if np.any(diff > limit):
            la, lb = sorted((int(linenos[a]), int(linenos[b])))
            raise MeasurementError(
                f"{where(source, lb)}same geometry as line {la} with a conflicting value "
                f"({values[a].tolist()} vs {values[b].tolist()}); average repeated measurements first"
            )


def _to_brdf_scale(quantity: str, theta_i: np.ndarray) -> np.ndarray:
    """Factor turning the file's quantity into f_r (docs/formats.md)."""
    if quantity == "brdf":
        return np.ones_like(theta_i)
    if quantity == "reflectance_factor":
        return np.full_like(theta_i, 1.0 / math.pi)
    with np.errstate(divide="ignore"):
        return 1.0 / np.cos(theta_i)


def format_measurement(m: Measurement) -> str:
    """The CSV text of ``m`` (values written as f_r, quantity ``brdf``)."""
    out = io.StringIO()
    meta = dict(m.metadata)
    meta["quantity"] = "brdf"
    out.write(f"# kesbrdf-measurement: {FORMAT_VERSION}\n")
    for key, value in meta.items():
        if key == "kesbrdf-measurement":
            continue
        if not isinstance(value, str):
            value = json.dumps(value)
        out.write(f"# {key}: {' '.join(str(value).split())}\n")
    in_plane = m.psi is not None and bool(np.all(np.isfinite(m.psi)))
    geometry = list(IN_PLANE_COLUMNS if in_plane else GENERAL_COLUMNS)
    value_cols = list(m.channels)
    unc_cols = [f"{c}_unc" for c in m.channels] if m.uncertainty is not None else []
    text_cols = [c for c in TEXT_COLUMNS if c in m.provenance]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(geometry + value_cols + unc_cols + text_cols)
    deg = {
        "psi_deg": np.degrees(m.psi) if in_plane else None,
        "theta_i_deg": np.degrees(m.theta_i),
        "theta_r_deg": np.degrees(m.theta_r),
        "phi_i_deg": np.degrees(m.phi_i),
        "phi_r_deg": np.degrees(m.phi_r),
    }
    for r in range(len(m)):
        row = [_fmt_angle(deg[c][r]) for c in geometry]
        row += [repr(float(v)) for v in m.values[r]]
        if unc_cols:
            row += [repr(float(v)) for v in m.uncertainty[r]]
        row += [str(m.provenance[c][r]) for c in text_cols]
        writer.writerow(row)
    return out.getvalue()


def _fmt_angle(x: float) -> str:
    """Degrees, rounded to 1e-9° so that radian round-off does not show (87, not 87.00000000000001)."""
    r = round(float(x), 9)
    return str(int(r)) if r == int(r) else repr(r)


def write_measurement(path, m: Measurement) -> Path:
    """Write ``m`` to ``path`` atomically in the measurement CSV format."""
    return write_text(path, format_measurement(m))
