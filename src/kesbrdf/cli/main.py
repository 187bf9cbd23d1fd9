"""The ``kesbrdf`` command line.

Each command lives in its own module ``kesbrdf.cli.<name>`` exposing

* ``HELP``: one line for the command list,
* ``add_arguments(parser)``: declare its flags,
* ``run(args) -> int``: parse nothing more, call one library function, report.

User errors (:class:`kesbrdf.errors.KesbrdfError`, missing files, missing optional
dependencies) and system errors (:class:`OSError`: disk full, read-only file system, ...;
writes through :mod:`kesbrdf._atomic` arrive as :class:`~kesbrdf.errors.OutputError`)
are printed on one line to stderr and give exit code 2; no traceback.
Set ``KESBRDF_DEBUG=1`` to see tracebacks.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError

#: Command name -> module name under kesbrdf.cli.  Order is the order of ``--help``.
COMMANDS: dict[str, str] = {
    "simulate": "simulate",
    "ingest": "ingest",
    "convert": "convert",
    "fit": "fit",
    "eval": "eval_",
    "validate": "validate",
    "plan": "plan",
    "plot": "plot",
    "report": "report",
    "render": "render",
    "drape": "drape",
    "colourways": "colourways",
    "export": "export",
    "compare-render": "compare_render",
    "view": "view",
    "demo": "demo",
    "showcase": "showcase",
    "batch": "batch",
}

EXIT_USER_ERROR = 2


def _load(name: str):
    try:
        return importlib.import_module(f"kesbrdf.cli.{COMMANDS[name]}")
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith("kesbrdf.cli."):
            return None
        raise


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (the project's error rule).

    argparse prints the whole usage block before its message; a user who mistyped a
    flag gets instead ``kesbrdf fit: error: <what> (see 'kesbrdf fit --help')`` and exit
    code 2, like every other user error.  Sub-parsers inherit the class.
    """

    def error(self, message):  # noqa: D102  (argparse API)
        text = " ".join(str(message).split())
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {text} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="kesbrdf",
        description="Anisotropic fabric BRDFs from four-orientation gonio measurements "
        "(extended KES).",
    )
    parser.add_argument("--version", action="version", version=f"kesbrdf {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = _load(name)
        if module is None:
            continue
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _parser=p)
    return parser


def error(message: str) -> None:
    """Print a one-line user error to stderr."""
    text = " ".join(str(message).split())
    print(f"kesbrdf: error: {text}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # name the command whose flags were mistyped, not the top-level parser
        words = list(sys.argv[1:] if argv is None else argv)
        command = getattr(args, "command", None)
        before_command = (command in words and extra[0] in words
                          and words.index(extra[0]) < words.index(command))
        owner = parser if before_command else getattr(args, "_parser", parser)
        owner.error(f"unrecognized arguments: {' '.join(extra)}")
    if not getattr(args, "_run", None):
        parser.print_help()
        return EXIT_USER_ERROR
    debug = os.environ.get("KESBRDF_DEBUG") == "1"
    try:
        return int(args._run(args) or 0)
    except (KesbrdfError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        if debug:
            raise
        if isinstance(exc, OSError) and exc.filename:
            error(f"{exc.filename}: {exc.strerror}")
        else:
            error(str(exc))
        return EXIT_USER_ERROR
    except OSError as exc:  # any other system error (a write outside kesbrdf._atomic, a read)
        if debug:
            raise
        from kesbrdf._atomic import describe

        error(f"{exc.filename}: {describe(exc, exc.filename)}" if exc.filename else str(exc))
        return EXIT_USER_ERROR
    except ImportError as exc:
        if debug:
            raise
        error(str(exc))
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        error("interrupted; finished outputs were kept, partial ones removed")
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
