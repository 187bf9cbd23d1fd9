"""``kesbrdf export MODEL --format FMT -o OUT``: write a model in another tool's format."""

from __future__ import annotations

import json

from kesbrdf.cli._common import check_output, stderr

HELP = "Export a model for other tools (Mitsuba/pbrt .bsdf, Mitsuba scene, ...); see docs/exports.md."


def add_arguments(p):
    p.add_argument("model", nargs="?", help="model file (.kes.json)")
    p.add_argument("--format", "-f", dest="fmt", help="export format (see --list)")
    p.add_argument("-o", "--output", help="file to write")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="format option (VALUE read as JSON when it parses, else as text); repeatable")
    p.add_argument("--list", action="store_true", help="list the export formats and exit")


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
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def agreement_line(agreement: dict) -> str:
    """One readable line of an export's agreement with the model.

    Scalars print as ``name=value``; a nested record (an analytic fit: material,
    parameters, error) prints only its error numbers, e.g. ``fit gltf_pbr: nrmse 0.528,
    nrmse_theta_le_70 0.46``.  The parameters are in the exported file itself.
    """
    parts = []
    for key, value in agreement.items():
        if not isinstance(value, dict):
            parts.append(f"{key}={_number(value)}")
            continue
        err = value.get("error") if isinstance(value.get("error"), dict) else value
        numbers = ", ".join(f"{k} {_number(v)}" for k, v in err.items()
                            if isinstance(v, (int, float)) and not isinstance(v, bool))
        label = f"{key} {value['material']}" if isinstance(value.get("material"), str) else key
        parts.append(f"{label}: {numbers}" if numbers else label)
    return "; ".join(parts)


def run(args) -> int:
    from kesbrdf.errors import ExportError
    from kesbrdf.export import export, format_module, format_names

    if args.list:
        for name in format_names():
            module = format_module(name)
            print(f"{name:24s} {getattr(module, 'HELP', '')}")
        return 0
    if not args.model or not args.fmt or not args.output:
        raise ExportError("export: expected MODEL, --format FMT and -o OUT (or --list)")
    check_output(args.output)  # the folder rule; the format's endings are checked by export()
    result = export(args.model, args.fmt, args.output, **parse_options(args.option))
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
    return 0
