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


def run(args) -> int:
    from kesbrdf.errors import KesbrdfError
    from kesbrdf.viewer.server import fit_csv_bytes, make_server

    if not 0 <= args.port <= 65535:
        raise KesbrdfError(f"--port: expected 0..65535, got {args.port}")
    if not 0 < args.max_upload_mb <= 4096:  # also refuses nan and inf
        raise KesbrdfError(f"--max-upload-mb: expected a positive size, got {args.max_upload_mb}")
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
        server.serve_forever()
    except KeyboardInterrupt:
        print("kesbrdf viewer: stopped", file=sys.stderr)
    finally:
        server.server_close()
    return 0
