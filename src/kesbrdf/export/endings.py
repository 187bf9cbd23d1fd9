"""The export format of an output file name (``kesbrdf export -o NAME.ext`` without ``--format``).

The endings are those the formats declare (``EXTENSIONS`` of each module of
:data:`kesbrdf.export.FORMATS`), so a new format is inferred as soon as it is registered.
Rules (docs/exports.md, "Format from the file name"):

* an ending that belongs to one format selects it: ``.gltf`` gltf, ``.glb`` glb,
  ``.mtlx`` mtlx, ``.usda``/``.usd`` usd, ``.xml`` mitsuba-scene, ``.brdf`` brdf-explorer;
* an ending shared by several formats (``.bsdf``: ``rgl-bsdf`` for Mitsuba 3 RGB,
  ``rgl-bsdf-spectral`` for pbrt-v4) or known to none is a one-line error listing the
  choices: the user adds ``--format``;
* an explicit format wins, but one whose endings do not include the output's is a
  one-line error naming the format the ending belongs to.

>>> format_for_output("satin.glb")
'glb'
"""

from __future__ import annotations

from pathlib import Path

from kesbrdf.errors import ExportError

__all__ = ["endings", "format_for_output", "resolve_format"]


def endings() -> dict[str, tuple[str, ...]]:
    """Ending (lower case, with the dot) -> the formats that write it, in ``FORMATS`` order."""
    from kesbrdf.export import FORMATS, format_module

    table: dict[str, tuple[str, ...]] = {}
    for fmt in FORMATS:
        for ext in getattr(format_module(fmt), "EXTENSIONS", ()) or ():
            table[ext.lower()] = table.get(ext.lower(), ()) + (fmt,)
    return table


def _ending_of(name: str, table) -> str | None:
    """The longest known ending ``name`` has (``.kes.json``-style double endings included)."""
    lower = name.lower()
    hits = [ext for ext in table if lower.endswith(ext)]
    return max(hits, key=len) if hits else None


def _choices(table) -> str:
    return ", ".join(f"{ext} ({' or '.join(fmts)})" for ext, fmts in table.items())


def format_for_output(out) -> str:
    """The one format whose endings include ``out``'s (module docstring).

    Raises
    ------
    ExportError
        The ending is shared by several formats or known to none; the message lists the
        endings and their formats.
    """
    name = Path(out).name
    table = endings()
    ext = _ending_of(name, table)
    if ext is None:
        got = Path(name).suffix or "no ending"
        raise ExportError(
            f"-o {out}: cannot tell the export format from {got!r}; expected one of {_choices(table)}, "
            "or give --format"
        )
    fmts = table[ext]
    if len(fmts) > 1:
        raise ExportError(f"-o {out}: the ending {ext} is written by {' and '.join(fmts)}; choose one with --format")
    return fmts[0]


def resolve_format(fmt: str | None, out) -> str:
    """``fmt`` when given and consistent with ``out``'s ending, else the format of the ending.

    Raises
    ------
    ExportError
        No ``fmt`` and an ending :func:`format_for_output` refuses, or a ``fmt`` whose
        endings do not include ``out``'s.
    """
    if fmt is None:
        return format_for_output(out)
    from kesbrdf.export import FORMATS, format_module

    if fmt not in FORMATS:
        return fmt  # kesbrdf.export.export names the known formats
    own = tuple(e.lower() for e in (getattr(format_module(fmt), "EXTENSIONS", ()) or ()))
    name = Path(out).name.lower()
    if not own or name.endswith(own):
        return fmt
    table = endings()
    ext = _ending_of(name, table)
    if ext:
        belongs = f"the ending of {' / '.join(table[ext])}: drop --format or change it"
    else:
        belongs = "an ending no format writes"
    raise ExportError(
        f"--format {fmt}: expected an output file ending in {' or '.join(own)}, got {Path(out).name!r} ({belongs})"
    )
