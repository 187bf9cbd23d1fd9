"""``kesbrdf export MODEL -o OUT [--format FMT]``: write a model in another tool's format.

Without ``--format`` the format comes from OUT's ending (:mod:`kesbrdf.export.endings`).
"""

from __future__ import annotations

import json

from kesbrdf.cli._common import check_output, stderr

HELP = "Export a model for other tools (Mitsuba/pbrt .bsdf, Mitsuba scene, ...); see docs/exports.md."


def add_arguments(p):
    p.add_argument("model", nargs="?", help="model file (.kes.json)")
    p.add_argument("--format", "-f", dest="fmt",
                   help="export format (see --list); default: from the ending of -o (.gltf, .glb, .mtlx, .usda/.usd, "
                   ".xml, .brdf; .bsdf needs rgl-bsdf or rgl-bsdf-spectral)")
    p.add_argument("-o", "--output", help="file to write")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="format option (VALUE read as JSON when it parses, else as text); repeatable")
    p.add_argument("--list", action="store_true", help="list the export formats and exit")
    p.add_argument("--check-look", action="store_true",
                   help="render the export in its own renderer (Mitsuba measured, Blender Cycles) and compare "
                        "it with the kesbrdf plugin's render of the model: FLIP, relative RMSE, noise floor "
                        "(docs/exports.md)")


def parse_options(items) -> dict:
    """``["n_theta=17", "name=felt"]`` -> ``{"n_theta": 17, "name": "felt"}``."""
    from kesbrdf.errors import ExportError

    options = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key.isidentifier():
            raise ExportError(f"--option: expected KEY=VALUE, got {item!r}")
        try:
            options[key] = json.loads(value)
        except ValueError:
            options[key] = value
    return options


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return f"{n} B"  # pragma: no cover


def _number(v) -> str:
    if isinstance(v, (list, tuple)):
        return ", ".join(_number(x) for x in v)
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numbers(err: dict) -> list[tuple[str, object]]:
    """The numbers of one error record, then the parameters at a bound (``at bound: ...``)."""
    numbers = [(k, v) for k, v in err.items() if _is_number(v)]
    bounds = err.get("at_bounds")
    if isinstance(bounds, list) and bounds:
        numbers.append(("at bound:", ", ".join(map(str, bounds))))
    return numbers


def _records(label: str, value: dict) -> list[tuple[str, list]]:
    """(label, [(name, number), ...]) of one nested agreement entry.

    An analytic fit (``material``, ``params``, ``error``) gives its error numbers; a
    dict of such records per variant (MaterialX: ``openpbr``, ``standard_surface``)
    gives one record per variant; a plain dict gives its numbers.
    """
    if isinstance(value.get("error"), dict):
        label = f"{label} {value['material']}" if isinstance(value.get("material"), str) else label
        return [(label, _numbers(value["error"]))]
    if value and all(isinstance(v, dict) for v in value.values()):
        return [r for sub, v in value.items()
                for r in _records(label if isinstance(v.get("material"), str) else f"{label} {sub}", v)]
    return [(label, _numbers(value))]


def agreement_line(agreement: dict) -> str:
    """One readable line of an export's agreement with the model.

    Scalars print as ``name=value``; a nested record (an analytic fit: material,
    parameters, error) prints only its error numbers, e.g. ``fit gltf_pbr: nrmse 0.528,
    nrmse_theta_le_70 0.46``, one record per variant when the export holds several
    (MaterialX, USD), and the parameters that ended at a bound of their physical range
    (``at bound: ior max``).  The parameters are in the exported file itself: when a short
    ``fit_error`` record (every variant's errors) is there, the full ``fit`` record is
    left out.
    """
    parts = []
    for key, value in agreement.items():
        if key == "fit" and isinstance(agreement.get("fit_error"), dict):
            continue
        if not isinstance(value, dict):
            parts.append(f"{key}={_number(value)}")
            continue
        for label, numbers in _records(key, value):
            text = ", ".join(f"{k} {_number(v)}" for k, v in numbers)
            parts.append(f"{label}: {text}" if text else label)
    return "; ".join(parts)


def run(args) -> int:
    from kesbrdf.errors import ExportError
    from kesbrdf.export import export, format_module, format_names

    if args.list:
        for name in format_names():
            module = format_module(name)
            print(f"{name:24s} {getattr(module, 'HELP', '')}")
        return 0
    from kesbrdf.export.endings import resolve_format

    if not args.model or not args.output:
        raise ExportError("export: expected MODEL and -o OUT (format from its ending, or --format FMT), or --list")
    check_output(args.output)  # the folder rule; the format's endings are checked by export()
    fmt = resolve_format(args.fmt, args.output)
    if args.check_look:  # before the (slow) export: a renderer for the format, and installed
        from kesbrdf.export.looks import require_renderer

        require_renderer(fmt)
    result = export(args.model, fmt, args.output, **parse_options(args.option))
    for p in result.paths:
        size = p.stat().st_size if p.is_file() else 0
        print(f"wrote {p} ({_size(size)})")
    if len(result.paths) > 1:
        print(f"total {_size(result.size)}")
    if result.agreement:
        print("agreement with the model: " + agreement_line(result.agreement))
    for note in result.notes:
        print(f"note: {note}")
    if result.open_with:
        print(f"open with: {result.open_with}")
    stderr(f"exported {args.model} as {result.format}")
    if args.check_look:
        from kesbrdf.export.looks import check_look, look_line

        look = check_look(args.model, result.format, result.paths[0])
        for row in look["rows"]:
            print(look_line(row))
            if "side_by_side" in row.get("images", {}):
                print(f"wrote {row['images']['side_by_side']}")
    return 0
