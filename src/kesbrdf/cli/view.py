"""``kesbrdf view``: serve the interactive web viewer on this machine."""

from __future__ import annotations

import sys
from pathlib import Path

HELP = "open the interactive viewer (plots, 3-D model, real-time preview) in the browser"


def add_arguments(parser) -> None:
    parser.add_argument(
        "input",
        nargs="?",
        metavar="MODEL_OR_CSV",
        help="a model file (*.kes.json) or a measurement CSV to fit and open",
    )
    parser.add_argument("--port", type=int, default=8765, help="TCP port (0: any free port); default 8765")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind; default 127.0.0.1 (this machine only)")
    parser.add_argument("--no-browser", action="store_true", help="only print the URL, do not open a browser")
    parser.add_argument(
        "--models",
        metavar="DIR",
        action="append",
        default=[],
        help="also list the *.kes.json models in DIR (repeatable); default: the input's folder",
    )
    parser.add_argument(
        "--measurement",
        metavar="CSV",
        help="measurement to compare the model with (default: the model's input file, if found unchanged)",
    )
    parser.add_argument(
        "--max-upload-mb",
        type=float,
        default=5.0,
        help="largest measurement CSV the page may upload, MB; default 5",
    )
    from kesbrdf.viewer import limits as L

    parser.add_argument(
        "--head-timeout-s", type=float, default=L.HEAD_TIMEOUT_S,
        help=f"seconds a request's head (request line and headers) may take in all; default {L.HEAD_TIMEOUT_S:g}",
    )
    parser.add_argument(
        "--body-timeout-s", type=float, default=L.BODY_TIMEOUT_S,
        help=f"seconds an upload's body may take in all; default {L.BODY_TIMEOUT_S:g}",
    )
    parser.add_argument(
        "--fit-cpu-s", type=float, default=L.FIT_CPU_S,
        help=f"CPU seconds the fit of one upload may use (422 beyond); default {L.FIT_CPU_S:g}",
    )
    parser.add_argument(
        "--fit-wall-s", type=float, default=L.FIT_WALL_S,
        help=f"seconds the fit of one upload may take (422 beyond); default {L.FIT_WALL_S:g}",
    )
    parser.add_argument(
        "--fit-workers", type=int, default=L.FIT_WORKERS,
        help=f"fits of uploads running at once, each in its own process; default {L.FIT_WORKERS}",
    )
    budgets = ", ".join(f"{k}={v}" for k, v in L.MAX_FIT_VALUES_BY_KIND.items())
    parser.add_argument(
        "--max-fit-values", metavar="[KIND=]N", action="append", default=[],
        help=f"rows x channels an upload may have (413 beyond), for every kind or for one fitted kind "
        f"(repeatable); default {L.MAX_FIT_VALUES} and {budgets}",
    )


#: ViewerLimits field -> the flag that sets it (for error messages).
_FLAGS = {
    "head_timeout_s": "--head-timeout-s",
    "body_timeout_s": "--body-timeout-s",
    "fit_cpu_s": "--fit-cpu-s",
    "fit_wall_s": "--fit-wall-s",
    "fit_workers": "--fit-workers",
    "max_fit_values": "--max-fit-values",
    "fit_values_by_kind": "--max-fit-values",
}


def _limits(args):
    """The server's :class:`ViewerLimits` from the flags (errors name the flag)."""
    from kesbrdf.errors import KesbrdfError, validate_choice
    from kesbrdf.models.base import known_fitters
    from kesbrdf.viewer.limits import MAX_FIT_VALUES, MAX_FIT_VALUES_BY_KIND, ViewerLimits

    max_values, by_kind = MAX_FIT_VALUES, dict(MAX_FIT_VALUES_BY_KIND)
    for text in args.max_fit_values:
        kind, _, number = text.rpartition("=")
        try:
            n = int(number)
        except ValueError:
            raise KesbrdfError(f"--max-fit-values: expected N or KIND=N with a whole number N, got {text!r}") from None
        if kind:
            validate_choice("--max-fit-values KIND", kind, known_fitters())
            by_kind[kind] = n
        else:
            max_values = n
    try:
        return ViewerLimits(
            head_timeout_s=args.head_timeout_s,
            body_timeout_s=args.body_timeout_s,
            fit_cpu_s=args.fit_cpu_s,
            fit_wall_s=args.fit_wall_s,
            fit_workers=args.fit_workers,
            max_fit_values=max_values,
            fit_values_by_kind=by_kind,
        )
    except KesbrdfError as exc:
        message = str(exc)
        field = message.split(":", 1)[0].split("[", 1)[0]
        raise KesbrdfError(_FLAGS.get(field, field) + message[len(message.split(":", 1)[0]):]) from None


def run(args) -> int:
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.viewer.server import fit_csv_bytes, make_server

    if not 0 <= args.port <= 65535:
        raise KesbrdfError(f"--port: expected 0..65535, got {args.port}")
    if not 0 < args.max_upload_mb <= 4096:  # also refuses nan and inf
        raise KesbrdfError(f"--max-upload-mb: expected a positive size, got {args.max_upload_mb}")
    limits = _limits(args)
    model_files: list[Path] = []
    model_dirs = [Path(d) for d in args.models]
    initial_upload = None
    if args.input:
        path = Path(args.input)
        if not path.is_file():
            raise FileNotFoundError(2, "No such file", str(path))
        if path.suffix.lower() == ".csv":
            model_json, measurement_json = fit_csv_bytes(path.read_bytes(), path.name)
            initial_upload = (path.name, model_json, measurement_json)
        else:
            model_files.append(path)
        if not args.models:
            model_dirs.append(path.resolve().parent)
    if args.measurement and not Path(args.measurement).is_file():
        raise FileNotFoundError(2, "No such file", args.measurement)
    for d in model_dirs:
        if not d.is_dir():
            raise KesbrdfError(f"--models: expected a folder, got {d}")
    try:
        server = make_server(
            model_files=model_files,
            model_dirs=model_dirs,
            host=args.host,
            port=args.port,
            max_upload_bytes=int(args.max_upload_mb * 1024 * 1024),
            initial_upload=initial_upload,
            measurement=args.measurement if model_files else None,
            limits=limits,
        )
    except OSError as exc:
        raise KesbrdfError(
            f"cannot listen on {args.host}:{args.port}: {exc.strerror or exc}; try --port 0"
        ) from None
    url = server.url
    if not server.loopback:
        print(
            f"kesbrdf viewer: listening on {args.host}: other machines can reach it (uploads are fitted here)",
            file=sys.stderr,
        )
    print(f"kesbrdf viewer: {url}  (Ctrl-C to stop)", flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(url)
    try:
        server.serve_forever()  # returns after Ctrl-C or SIGTERM (uvicorn handles both)
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
    print("kesbrdf viewer: stopped", file=sys.stderr)
    return 0
