"""Open any measurement source by path: measurement CSV, CUReT, RGL ``.bsdf``, MERL ``.binary``.

``kesbrdf fit`` and ``kesbrdf convert`` take one input path; this module says what it is
and turns it into a :class:`~kesbrdf.measure.measurement.Measurement` (docs/formats.md,
"Inputs kesbrdf reads directly").

Kinds of input (:data:`KINDS`)
------------------------------
``measurement-csv``
    kesbrdf's own CSV (:mod:`kesbrdf.io.measurement_csv`), read as it is.
``curet``
    The CUReT BRDF database (:mod:`kesbrdf.io.curet`): ``abrdf.dat`` with ``table.txt``
    beside it (or either file, or the folder holding both).  The file holds 61 samples,
    so one is chosen by number or by fabric name (:func:`curet_sample`).  Scattered
    (general-geometry) rows: ``kesbrdf fit`` uses the scattered fitter.
``rgl-bsdf``
    An RGL-EPFL tensor file (Dupuy & Jakob 2018), evaluated in numpy by
    :class:`~kesbrdf.references.rgl_tensor.RGLTensorBRDF` (no Mitsuba needed).
``merl-binary``
    A MERL ``.binary`` (Matusik et al. 2003), :class:`~kesbrdf.references.merl.MERLBinary`.

The last two are BRDF *tables*, not measurements: they are sampled at the geometries
of a protocol by the virtual gonioreflectometer (:func:`kesbrdf.measure.gonio.measure`, the code
``kesbrdf simulate`` uses), so a database material is "measured" exactly as a fabric
would be.  The rows are labelled ``simulated: true`` (the geometry is virtual) and carry
the table's file name and sha256 in ``resampled_from``.

Recognition (:func:`detect`) looks at the content first (the tensor-file magic
``tensor_file\\0``; MERL's 12-byte header ``90 90 180``), then at the name (``.csv``,
``abrdf.dat``/``table.txt``, ``.bsdf``, ``.binary``), then sniffs text: a ``#`` header or
a comma-separated first line is a CSV; whitespace-separated numbers with ``table.txt``
beside them are CUReT.  Anything else is a one-line error listing the kinds.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from kesbrdf.errors import FormatError, KesbrdfError, where

__all__ = ["KINDS", "TABLE_KINDS", "detect", "read_source", "reference_from_file", "curet_sample",
           "curet_files", "describe_kinds"]

#: Inputs kesbrdf reads directly, in the order error messages list them.
KINDS = ("measurement-csv", "curet", "rgl-bsdf", "merl-binary")
#: Kinds that are BRDF tables (sampled at a protocol's geometries), not measurements.
TABLE_KINDS = ("rgl-bsdf", "merl-binary")

CURET_DATA = "abrdf.dat"
CURET_TABLE = "table.txt"

#: Bytes read to recognise a file by content.
_SNIFF_BYTES = 4096


def describe_kinds() -> str:
    """One phrase naming every input kind, for error messages and ``--help``."""
    return ("a measurement CSV (.csv), CUReT abrdf.dat (with table.txt beside it), "
            "an RGL tensor file (.bsdf) or a MERL .binary")


def _is_merl_header(head: bytes) -> bool:
    from kesbrdf.references.merl import DIMS

    if len(head) < 12:
        return False
    import numpy as np

    return tuple(int(v) for v in np.frombuffer(head[:12], "<i4")) == DIMS


def curet_files(path) -> tuple[Path, Path]:
    """(table.txt, abrdf.dat) for a CUReT input given as either file or their folder.

    Raises
    ------
    FormatError
        The partner file is not beside the one given (CUReT keeps the two together).
    """
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    if path.is_dir():
        table, data = folder / CURET_TABLE, folder / CURET_DATA
    elif path.name.lower() == CURET_TABLE:
        table, data = path, folder / CURET_DATA
    else:
        table, data = folder / CURET_TABLE, path
    for p, partner in ((table, "configuration table"), (data, "BRDF values")):
        if not p.is_file():
            raise FormatError(
                f"{where(path)}CUReT input: expected {p.name} ({partner}) in {folder}, found none "
                f"(CUReT's {CURET_DATA} and {CURET_TABLE} are read together)"
            )
    return table, data


def detect(path) -> str:
    """The kind of input ``path`` is, one of :data:`KINDS` (module docstring).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    FormatError
        Not a kind kesbrdf reads (one line listing them).
    """
    path = Path(path)
    if path.is_dir():
        if (path / CURET_DATA).is_file() or (path / CURET_TABLE).is_file():
            return "curet"
        raise FormatError(f"{where(path)}expected {describe_kinds()}; got a folder without {CURET_DATA}")
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    from kesbrdf.io.tensor_file import MAGIC

    with path.open("rb") as fh:
        head = fh.read(_SNIFF_BYTES)
    if head.startswith(MAGIC):
        return "rgl-bsdf"
    if _is_merl_header(head):
        return "merl-binary"
    name = path.name.lower()
    by_name = {".csv": "measurement-csv", ".bsdf": "rgl-bsdf", ".binary": "merl-binary"}
    if name in (CURET_DATA, CURET_TABLE):
        return "curet"
    if path.suffix.lower() in by_name:
        return by_name[path.suffix.lower()]
    text = head.decode("utf-8", "replace").lstrip("\ufeff")
    first = next((line.strip() for line in text.splitlines() if line.strip()), "")
    if first.startswith("#") or "," in first:
        return "measurement-csv"
    fields = first.split()
    numeric = bool(fields) and all(re.fullmatch(r"[-+0-9.eE]+", f) for f in fields)
    if numeric and (path.parent / CURET_TABLE).is_file():
        return "curet"
    if not head:
        got = "an empty file"
    elif "\ufffd" in text or "\0" in text:
        got = "binary data"
    else:
        got = f"text starting {first[:40]!r}"
    raise FormatError(f"{where(path)}expected {describe_kinds()}; got {got}")


def curet_sample(spec) -> int:
    """A CUReT sample number from ``--sample``: a number (``42``) or a fabric name (``corduroy``).

    Names are those of :data:`kesbrdf.io.curet.FABRICS`, matched ignoring case, spaces and
    punctuation (``polyester-zoomed`` is sample 29).

    Raises
    ------
    KesbrdfError
        No sample given, or a name that is not a CUReT fabric (the message lists them).
    """
    from kesbrdf.io.curet import FABRICS

    listing = ", ".join(f"{k} {v}" for k, v in FABRICS.items())
    if spec is None or not str(spec).strip():
        raise KesbrdfError(
            f"--sample: a CUReT file holds 61 samples; expected a sample number or a fabric name "
            f"({listing}), got none"
        )
    text = str(spec).strip()
    if re.fullmatch(r"[0-9]+", text):
        return int(text)
    key = re.sub(r"[^a-z0-9]", "", text.lower())
    for number, name in FABRICS.items():
        if re.sub(r"[^a-z0-9]", "", name.lower()) == key:
            return number
    raise KesbrdfError(f"--sample: expected a CUReT sample number or a fabric name ({listing}), got {text!r}")


def reference_from_file(path, parameterised_by: str = "viewer"):
    """The BRDF table in ``path`` as a reference callable f(wi, wr) -> (..., 3) in 1/sr.

    RGL tensor files are read by :class:`~kesbrdf.references.rgl_tensor.RGLTensorBRDF`
    (numpy; the same algorithm as Mitsuba's ``measured`` plugin), MERL files by
    :class:`~kesbrdf.references.merl.MERLBinary`.  ``parameterised_by`` (RGL only) is the
    direction put in the table's incident axes; the default ``"viewer"`` is the one the
    built-in ``rgl-felt-*`` references use, so a path and a name give the same BRDF.

    Raises
    ------
    FormatError
        ``path`` is not a BRDF table (a measurement is read with :func:`read_source`).
    """
    kind = detect(path)
    if kind == "rgl-bsdf":
        from kesbrdf.references.rgl_tensor import RGLTensorBRDF

        return RGLTensorBRDF(path, parameterised_by=parameterised_by)
    if kind == "merl-binary":
        from kesbrdf.references.merl import MERLBinary

        return MERLBinary(path)
    raise FormatError(f"{where(path)}expected a BRDF table (an RGL .bsdf or a MERL .binary), got a {kind} file")


def _table_sample_name(brdf, path: Path) -> str:
    description = getattr(brdf, "description", "") or path.stem
    return f"{description} ({path.name})"


def read_source(path, *, sample=None, protocol: str | None = None, step_deg: float | None = None,
                orientations_deg=None):
    """A :class:`~kesbrdf.measure.measurement.Measurement` from any input kind (module docstring).

    Parameters
    ----------
    path : path-like
        The input (a file, or a CUReT folder).
    sample : int or str, optional
        CUReT only, and required there: the sample number or fabric name.
    protocol, step_deg, orientations_deg : optional
        BRDF tables only: the geometries they are sampled at (:func:`kesbrdf.measure.gonio.measure`;
        default the paper's protocol and orientations).

    Returns
    -------
    Measurement
        ``source`` is ``path`` and ``sha256`` the hash of the file read.

    Raises
    ------
    KesbrdfError
        Unrecognised input, a malformed file (file:line), or an option that does not
        apply to this kind (``--sample`` on a CSV, ``--protocol`` on a measurement).
    """
    path = Path(path)
    kind = detect(path)
    table_only = {"--protocol": protocol, "--step-deg": step_deg, "--orientations-deg": orientations_deg}
    if kind != "curet" and sample is not None:
        raise KesbrdfError(f"--sample: applies to CUReT input only; {path} is a {kind} file")
    if kind not in TABLE_KINDS:
        given = [flag for flag, v in table_only.items() if v is not None]
        if given:
            raise KesbrdfError(
                f"{given[0]}: applies to BRDF tables (RGL .bsdf, MERL .binary) only; {path} is a {kind} "
                "file, whose geometries are its own"
            )
    if kind == "measurement-csv":
        from kesbrdf.io.measurement_csv import read_measurement

        return read_measurement(path)
    if kind == "curet":
        from kesbrdf.io.curet import read_curet

        number = curet_sample(sample)
        table, data = curet_files(path)
        return read_curet(table, data, number)
    from kesbrdf.measure.gonio import measure
    from kesbrdf.measure.measurement import PAPER_ORIENTATIONS_DEG

    brdf = reference_from_file(path)
    m = measure(
        brdf,
        protocol=protocol or "paper",
        step_deg=step_deg,
        orientations_deg=PAPER_ORIENTATIONS_DEG if orientations_deg is None else orientations_deg,
        sample=_table_sample_name(brdf, path),
    )
    sha = getattr(brdf, "sha256", None) or hashlib.sha256(path.read_bytes()).hexdigest()
    m.metadata["resampled_from"] = (
        f"{path.name} sha256:{sha} ({kind}, measured data sampled at the protocol's geometries)"
    )
    m.source = str(path)
    m.sha256 = sha
    return m
