"""Local HTTP server of the web viewer: static bundle plus a small JSON API.

An ASGI application served by uvicorn (HTTP/1.1 through h11; docs/decisions.md, "Viewer
server").  The server binds to 127.0.0.1 by default
and serves

* the built viewer bundle from ``kesbrdf/viewer/static/`` (``GET /``, ``GET /assets/...``);
* ``GET /api/config``: ``{"initial": id or null, "max_upload_bytes": n, "version": ...}``;
* ``GET /api/models``: ``{"models": [{"id", "name", "kind", "has_measurement"}]}``;
* ``GET /api/model/<id>``: ``{"id", "name", "model": <the model file JSON, docs/formats.md;
  for a kind without a (φ, γ) table its tabulated view>,
  "measurement": <see :func:`measurement_to_json`> or null}``;
* ``POST /api/fit?name=<file name>[&fallback=error|log]`` with the raw CSV bytes as body:
  reads it with :func:`kesbrdf.io.measurement_csv.read_measurement`, fits it with
  :func:`kesbrdf.fit` with its defaults (kind chosen from the data, as ``kesbrdf fit``
  with ``--no-compare``, the comparison with the prior being beyond an upload's budget;
  ``fallback=error`` is ``--strict``, ``log`` the default), keeps the result in memory
  and answers like ``/api/model``.  The fit runs in a child process within a work
  budget (:mod:`kesbrdf.viewer.fit_job`).

Errors come back as ``{"error": "<one line>"}`` with a 4xx/5xx status (the same message
the CLI prints for the same input); the server keeps running.  Request bodies larger
than ``max_upload_bytes`` are refused with 413 before they are read.

Limits (:class:`kesbrdf.viewer.limits.ViewerLimits`; docs/formats.md, "Viewer server
limits"): a request's head must be complete within ``head_timeout_s`` and its body within
``body_timeout_s`` (whole-request deadlines: 408 and closed); at most
``max_connections`` connections are open at once (further ones closed at accept), with a
listen backlog of ``backlog``; file and JSON work runs on ``worker_threads`` threads; an
upload is refused with 413 before fitting when it has too many channels or rows x
channels for the kind it would be fitted with, and with 422 when its fit runs out of
``fit_cpu_s`` CPU seconds or ``fit_wall_s`` seconds; a fitted answer larger than
``max_response_bytes`` is refused with 413; fitted uploads are kept in a cache of at most
:data:`MAX_UPLOADS_KEPT` entries and :data:`MAX_UPLOAD_CACHE_BYTES` bytes (oldest
dropped first; the model given on the command line is kept).  Only files inside the
static folder and the model files listed by ``/api/models`` are reachable: every static
path is resolved (symlinks included) and must stay inside the static folder; models are
addressed by id, never by path.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import threading
import urllib.parse
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError, ModelError, where, validate_choice
from kesbrdf.viewer.limits import (
    DEFAULT_MAX_UPLOAD_BYTES,
    HEAD_TIMEOUT_S,
    BODY_TIMEOUT_S,
    MAX_CONNECTIONS,
    MAX_FIT_CHANNELS,
    MAX_FIT_VALUES,
    MAX_RESPONSE_BYTES,
    MAX_UPLOADS_KEPT,
    MAX_UPLOAD_CACHE_BYTES,
    ViewerLimits,
)
from kesbrdf.viewer.upload import (
    UploadTooLarge,
    check_upload_work,
    fit_csv_bytes,
    measurement_to_json,
    safe_upload_name,
)

__all__ = [
    "DEFAULT_MAX_UPLOAD_BYTES",
    "STATIC_DIR",
    "ModelEntry",
    "ModelStore",
    "ViewerLimits",
    "ViewerServer",
    "make_server",
    "load_model_json",
    "fit_csv_bytes",
    "find_input_measurement",
    "measurement_to_json",
    "check_upload_work",
    "UploadTooLarge",
    "HEAD_TIMEOUT_S",
    "BODY_TIMEOUT_S",
    "MAX_CONNECTIONS",
    "MAX_FIT_CHANNELS",
    "MAX_FIT_VALUES",
    "MAX_RESPONSE_BYTES",
    "MAX_UPLOADS_KEPT",
    "MAX_UPLOAD_CACHE_BYTES",
]

#: The built bundle shipped inside the package (``make viewer-bundle``).
STATIC_DIR = Path(__file__).resolve().parent / "static"

#: The ``Server`` header of every answer.
SERVER_NAME = f"kesbrdf-view/{__version__}"

_CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".json": "application/json",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".ico": "image/x-icon",
    ".txt": "text/plain; charset=utf-8",
    ".map": "application/json",
}
_LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1"}
_MODEL_SUFFIXES = (".kes.json",)


# -- models -----------------------------------------------------------------------
def load_model_json(path: str | os.PathLike) -> dict:
    """Read and check a model file; return its JSON document unchanged.

    Uses :func:`kesbrdf.io.model_file.load_model` for the full check first, so the
    error is the one the CLI gives for the same file.  A model without its own (φ, γ)
    table is returned as its tabulated view (:func:`kesbrdf.viewer.upload.view_document`),
    so the viewer draws every kind.

    Raises
    ------
    ModelError
        Not JSON, not a kesbrdf model, or an unknown format version.
    """
    from kesbrdf.io.model_file import load_model

    path = Path(path)
    model = load_model(path)  # first, so that the error is the CLI's for the same file
    if not model.has_table:
        from kesbrdf.viewer.upload import view_document

        return view_document(model)
    from kesbrdf.io.text import decode_text

    text = decode_text(path.read_bytes(), path)
    try:
        doc = json.loads(text)
    except RecursionError:
        raise ModelError(f"{where(path)}expected a kesbrdf model (JSON), got JSON nested too deeply") from None
    except json.JSONDecodeError as exc:
        raise ModelError(
            f"{where(path, exc.lineno)}expected a kesbrdf model (JSON), got invalid JSON: {exc.msg}"
        ) from None
    if not isinstance(doc, dict) or doc.get("format") != "kesbrdf-model":
        raise ModelError(f"{where(path)}expected a kesbrdf model file (format 'kesbrdf-model')")
    if doc.get("format_version") != 1:
        raise ModelError(
            f"{where(path)}expected model format_version 1, got {doc.get('format_version')!r}"
        )
    return doc



def find_input_measurement(model_path: str | os.PathLike, model_doc: dict) -> dict | None:
    """The measurement a model was fitted from, if its recorded input file is still there.

    Looks for ``input.name`` as recorded (absolute, or relative to the model's folder),
    then for a file of that name beside the model; uses it only when its SHA-256
    equals ``input.sha256``, so a changed or unrelated file is never paired.
    """
    import hashlib

    info = model_doc.get("input") or {}
    name, digest = info.get("name"), info.get("sha256")
    if not isinstance(name, str) or not isinstance(digest, str) or not digest:
        return None
    folder = Path(model_path).resolve().parent
    for candidate in (Path(name), folder / name, folder / Path(name).name):
        try:
            if candidate.is_file() and hashlib.sha256(candidate.read_bytes()).hexdigest() == digest:
                from kesbrdf.io.measurement_csv import read_measurement

                return measurement_to_json(read_measurement(candidate))
        except (OSError, KesbrdfError):
            continue
    return None


@dataclass
class ModelEntry:
    """One model the server can hand out: from a file or from an upload."""

    id: str
    name: str
    kind: str  # "file" | "upload"
    path: Path | None = None
    model: dict | None = None
    measurement: dict | None = None


@dataclass
class ModelStore:
    """The models the viewer may load: files in the model folders plus fitted uploads.

    Files are addressed by an id (``f<n>``) assigned when the folders are scanned,
    never by a path from the request, so nothing outside these folders is reachable.
    """

    model_dirs: list[Path] = field(default_factory=list)
    model_files: list[Path] = field(default_factory=list)
    entries: dict[str, ModelEntry] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    max_uploads: int = MAX_UPLOADS_KEPT
    max_upload_bytes: int = MAX_UPLOAD_CACHE_BYTES
    _uploads: int = 0
    _upload_sizes: dict = field(default_factory=dict)  # id -> JSON bytes, oldest first
    _pinned: set = field(default_factory=set)

    def scan(self) -> list[ModelEntry]:
        """Refresh file entries from ``model_files`` and ``*.kes.json`` in ``model_dirs``."""
        paths: list[Path] = [Path(p).resolve() for p in self.model_files]
        for folder in self.model_dirs:
            folder = Path(folder).resolve()
            if folder.is_dir():
                for p in sorted(folder.iterdir()):
                    if p.name.endswith(_MODEL_SUFFIXES) and p.is_file():
                        real = p.resolve()
                        # a symlink pointing out of the folder is not listed
                        if real.is_relative_to(folder):
                            paths.append(real)
        with self.lock:
            known = {e.path: e for e in self.entries.values() if e.kind == "file"}
            for p in dict.fromkeys(paths):
                if p not in known:
                    entry_id = f"f{sum(e.kind == 'file' for e in self.entries.values())}"
                    self.entries[entry_id] = ModelEntry(entry_id, p.name, "file", path=p)
            return list(self.entries.values())

    def add_upload(
        self, name: str, model: dict, measurement: dict | None, size: int | None = None, pinned: bool = False
    ) -> ModelEntry:
        """Keep a fitted upload; drop the oldest unpinned ones beyond the count and size limits.

        ``size`` is the entry's JSON size in bytes (computed when not given).
        """
        if size is None:
            size = len(json.dumps(model)) + len(json.dumps(measurement))
        with self.lock:
            self._uploads += 1
            entry_id = f"u{self._uploads}"
            entry = ModelEntry(entry_id, name, "upload", model=model, measurement=measurement)
            self.entries[entry_id] = entry
            self._upload_sizes[entry_id] = int(size)
            if pinned:
                self._pinned.add(entry_id)
            self._evict()
            return entry

    def _evict(self) -> None:
        """Drop the oldest unpinned uploads until the cache is within its limits (lock held)."""
        for old in list(self._upload_sizes):
            count = len(self._upload_sizes)
            total = sum(self._upload_sizes.values())
            if count <= self.max_uploads and total <= self.max_upload_bytes:
                return
            if old in self._pinned or old == next(reversed(self._upload_sizes)):
                continue  # the pinned upload and the newest one stay
            del self._upload_sizes[old]
            self.entries.pop(old, None)

    @property
    def upload_cache(self) -> tuple[int, int]:
        """(uploads kept, their total JSON bytes)."""
        with self.lock:
            return len(self._upload_sizes), sum(self._upload_sizes.values())

    def get(self, entry_id: str) -> ModelEntry | None:
        with self.lock:
            return self.entries.get(entry_id)


# -- HTTP ---------------------------------------------------------------------------
@dataclass
class _Answer:
    status: int
    body: bytes
    content_type: str = "application/json"
    close: bool = False


def _json(status: int, doc, close: bool = False) -> _Answer:
    return _Answer(status, json.dumps(doc).encode("utf-8"), "application/json", close)


def _error(status: int, message: str, close: bool = False) -> _Answer:
    return _json(status, {"error": " ".join(str(message).split())}, close=close)


@dataclass
class _Request:
    """The parts of an ASGI request the routes read (path undecoded, as sent)."""

    method: str
    path: str
    query: dict
    headers: dict = field(default_factory=dict)  # lower-case name -> first value

    @classmethod
    def from_scope(cls, scope: dict) -> "_Request":
        headers: dict[str, str] = {}
        for name, value in scope["headers"]:
            headers.setdefault(name.decode("latin-1").lower(), value.decode("latin-1"))
        raw = scope.get("raw_path") or scope["path"].encode("utf-8")
        return cls(
            method=scope["method"],
            path=raw.decode("latin-1"),
            query=urllib.parse.parse_qs(scope.get("query_string", b"").decode("latin-1")),
            headers=headers,
        )


async def _read_body(receive, length: int) -> bytes | None:
    """The request body (``length`` bytes announced), or None when the client went away."""
    chunks, size = [], 0
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            return None
        chunk = message.get("body", b"")
        chunks.append(chunk)
        size += len(chunk)
        if size > length:  # h11 enforces Content-Length; never keep more than announced
            return None
        if not message.get("more_body", False):
            return b"".join(chunks)


class ViewerApp:
    """The viewer's ASGI application: routes, model store, fits (module docstring)."""

    def __init__(self, server: "ViewerServer") -> None:
        self.server = server
        from kesbrdf.viewer.fit_job import FitRunner

        self.fits = FitRunner(server.limits)

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] == "lifespan":
            return await self._lifespan(receive, send)
        if scope["type"] != "http":
            return
        req = _Request.from_scope(scope)
        try:
            answer = await self._dispatch(req, receive)
        except Exception as exc:  # keep serving whatever happens
            answer = _error(500, f"internal error: {type(exc).__name__}: {exc}", close=req.method == "POST")
        if answer is None:  # the client went away
            return
        headers = [
            (b"content-type", answer.content_type.encode()),
            (b"content-length", str(len(answer.body)).encode()),
            (b"cache-control", b"no-store"),
            (b"x-content-type-options", b"nosniff"),
        ]
        if answer.close:
            headers.append((b"connection", b"close"))
        await send({"type": "http.response.start", "status": answer.status, "headers": headers})
        await send({"type": "http.response.body", "body": answer.body})

    async def _lifespan(self, receive, send) -> None:
        """ASGI lifespan: stop the warm fit process at shutdown."""
        while True:
            message = await receive()
            if message["type"] == "lifespan.startup":
                await send({"type": "lifespan.startup.complete"})
            elif message["type"] == "lifespan.shutdown":
                await self.fits.close()
                await send({"type": "lifespan.shutdown.complete"})
                return

    async def _dispatch(self, req: _Request, receive) -> _Answer | None:
        loop = asyncio.get_running_loop()
        if req.method == "GET" and req.path in ("/", "/index.html"):
            self.fits.prepare()  # the page is opening: an upload may follow
        if req.method in ("GET", "HEAD"):
            return await loop.run_in_executor(self.server.executor, self._get, req)
        if req.method == "POST":
            foreign = self._foreign(req)
            if foreign is not None:
                return foreign
            parsed = urllib.parse.urlsplit(req.path)
            if parsed.path != "/api/fit":
                return _error(404, f"unknown API endpoint {parsed.path}", close=True)
            return await self._post_fit(req, receive)
        return _error(501, f"expected GET, HEAD or POST, got {req.method}", close=True)

    # -- routing
    def _foreign(self, req: _Request) -> _Answer | None:
        """A 403 for requests another web site makes through the user's browser, else None.

        On a loopback address the Host header must name this machine (no DNS
        rebinding), and a request that carries an Origin must come from the viewer's
        own origin (no cross-site uploads).
        """
        host = (req.headers.get("host") or "").strip().lower()
        hostname = urllib.parse.urlsplit(f"//{host}").hostname or ""
        if self.server.loopback and hostname not in _LOOPBACK_NAMES:
            return _error(403, f"expected a request to this machine, got Host {host!r}", close=True)
        origin = req.headers.get("origin")
        if origin is not None and urllib.parse.urlsplit(origin).netloc.lower() != host:
            return _error(403, f"expected a request from the viewer's page, got Origin {origin!r}", close=True)
        return None

    def _get(self, req: _Request) -> _Answer:
        """GET and HEAD (on a worker thread: reads files, encodes JSON)."""
        foreign = self._foreign(req)
        if foreign is not None:
            return foreign
        path = urllib.parse.urlsplit(req.path).path
        if path == "/api/config":
            return _json(200, self.server.config())
        if path == "/api/models":
            entries = self.server.store.scan()
            return _json(200, {"models": [_entry_summary(e) for e in entries]})
        if path.startswith("/api/model/"):
            return self._get_model(urllib.parse.unquote(path[len("/api/model/"):]))
        if path.startswith("/api/"):
            return _error(404, f"unknown API endpoint {path}")
        return self._static(path)

    def _get_model(self, entry_id: str) -> _Answer:
        store = self.server.store
        entry = store.get(entry_id)
        if entry is None:
            store.scan()
            entry = store.get(entry_id)
        if entry is None:
            return _error(404, f"no model with id {entry_id!r}; see /api/models")
        if entry.kind == "file":
            try:
                model = load_model_json(entry.path)
            except (KesbrdfError, OSError) as exc:
                msg = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) else str(exc)
                return _error(422, msg)
            except Exception as exc:  # a loader bug must not look like a server crash: still the file's fault
                return _error(422, f"{where(entry.path)}cannot load model file: {type(exc).__name__}: {exc}")
            measurement = entry.measurement or find_input_measurement(entry.path, model)
        else:
            model, measurement = entry.model, entry.measurement
        return _json(200, {"id": entry.id, "name": entry.name, "model": model, "measurement": measurement})

    def _static(self, url_path: str) -> _Answer:
        target = self.server.resolve_static(url_path)
        if target is None:
            return _error(404, f"not found: {url_path}")
        ctype = _CONTENT_TYPES.get(target.suffix.lower(), "application/octet-stream")
        return _Answer(200, target.read_bytes(), ctype)

    async def _post_fit(self, req: _Request, receive) -> _Answer | None:
        limits = self.server.limits
        limit = self.server.max_upload_bytes
        if "chunked" in req.headers.get("transfer-encoding", "").lower():
            return _error(411, "expected a Content-Length, got a chunked upload", close=True)
        length_text = req.headers.get("content-length")
        if length_text is None:
            return _error(411, "expected a Content-Length header on the upload", close=True)
        try:
            length = int(length_text)
            if length < 0:
                raise ValueError
        except ValueError:
            return _error(400, f"expected a Content-Length, got {length_text!r}", close=True)
        if length > limit:
            # refuse without reading: the connection is closed after the reply
            return _error(413, f"upload too large: {length} bytes, limit {limit} bytes", close=True)
        try:
            async with asyncio.timeout(limits.body_timeout_s):  # whole body, not per read
                data = await _read_body(receive, length)
        except TimeoutError:
            return _error(
                408,
                f"upload incomplete after {limits.body_timeout_s:g} s (kesbrdf view --body-timeout-s); "
                f"expected {length} bytes",
                close=True,
            )
        if data is None:
            return None
        if len(data) != length:
            return _error(400, f"upload incomplete: expected {length} bytes, got {len(data)}", close=True)
        name = safe_upload_name((req.query.get("name") or ["upload.csv"])[0])
        fallback = (req.query.get("fallback") or [None])[0]
        try:
            if fallback is not None:
                validate_choice("fallback", fallback, ("error", "log"))
        except KesbrdfError as exc:
            return _error(400, str(exc))
        status, doc = await self.fits.fit(data, name, fallback)
        if status != 200:
            return _error(status, doc["error"])
        entry = self.server.store.add_upload(name, doc["model"], doc["measurement"], size=doc["size"])
        answer = {"id": entry.id, "name": entry.name, "model": doc["model"], "measurement": doc["measurement"]}
        return await asyncio.get_running_loop().run_in_executor(self.server.executor, _json, 200, answer)


def _entry_summary(entry: ModelEntry) -> dict:
    return {
        "id": entry.id,
        "name": entry.name,
        "kind": entry.kind,
        "has_measurement": entry.measurement is not None,
    }


class ViewerServer:
    """The viewer's HTTP server (uvicorn); bound and listening from construction on.

    ``serve_forever()`` serves until ``shutdown()`` (from another thread) or Ctrl-C;
    ``server_close()`` releases the socket and the worker threads.
    """

    def __init__(
        self,
        address: tuple[str, int],
        store: ModelStore,
        static_dir: str | os.PathLike = STATIC_DIR,
        max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
        initial: str | None = None,
        verbose: bool = False,
        limits: ViewerLimits | None = None,
    ) -> None:
        try:
            import uvicorn

            from kesbrdf.viewer.connection import protocol_class
        except ImportError as exc:
            raise KesbrdfError(f"the viewer server needs uvicorn ({exc}): pip install 'kesbrdf[viewer]'") from None
        self.limits = limits or ViewerLimits()
        self.store = store
        self.static_dir = Path(static_dir).resolve()
        self.max_upload_bytes = int(max_upload_bytes)
        self.initial = initial
        self.verbose = verbose
        host = str(address[0])
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        # listening from here on: connections wait in the backlog until serve_forever
        self.socket = socket.create_server(tuple(address), family=family, backlog=self.limits.backlog)
        self.server_address = self.socket.getsockname()
        self.loopback = host.startswith("127.") or host in ("::1", "localhost")
        self.executor = ThreadPoolExecutor(self.limits.worker_threads, thread_name_prefix="kesbrdf-view")
        config = uvicorn.Config(
            ViewerApp(self),
            http=protocol_class(self.limits, SERVER_NAME),
            loop="asyncio",
            ws="none",
            lifespan="on",
            interface="asgi3",
            proxy_headers=False,
            server_header=False,
            headers=[("Server", SERVER_NAME)],
            backlog=self.limits.backlog,
            timeout_keep_alive=self.limits.keep_alive_s,
            timeout_graceful_shutdown=2,
            h11_max_incomplete_event_size=self.limits.max_head_bytes,
            log_config=None,
            log_level="info" if verbose else "error",
            access_log=verbose,
        )
        self._uvicorn = uvicorn.Server(config)
        self._serving = threading.Event()
        self._stopped = threading.Event()
        self._stopped.set()

    def serve_forever(self, poll_interval: float = 0.5) -> None:
        """Serve until :meth:`shutdown` (``poll_interval`` is kept for compatibility: uvicorn polls every 0.1 s)."""
        self._stopped.clear()
        self._serving.set()
        try:
            self._uvicorn.run(sockets=[self.socket])
        finally:
            self._serving.clear()
            self._stopped.set()

    def shutdown(self) -> None:
        """Stop :meth:`serve_forever` and wait until it has returned."""
        self._uvicorn.should_exit = True
        if self._serving.is_set():
            self._stopped.wait()

    def server_close(self) -> None:
        """Close the listening socket and stop the worker threads."""
        self.socket.close()
        self.executor.shutdown(wait=False, cancel_futures=True)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/"

    def config(self) -> dict:
        return {
            "initial": self.initial,
            "max_upload_bytes": self.max_upload_bytes,
            "version": __version__,
        }

    def resolve_static(self, url_path: str) -> Path | None:
        """Map a URL path to a file inside the static folder, or None.

        Percent-decoding happens once; NUL bytes, backslashes and anything that
        resolves (symlinks followed) outside the static folder give None.
        """
        rel = urllib.parse.unquote(url_path)
        if "\x00" in rel or "\\" in rel:
            return None
        rel = rel.lstrip("/")
        if rel == "" or rel.endswith("/"):
            rel += "index.html"
        parts = rel.split("/")
        if any(p in ("..", "") for p in parts) or os.path.isabs(rel):
            return None
        try:
            target = (self.static_dir / rel).resolve(strict=True)
        except (OSError, RuntimeError):
            return None
        if not target.is_relative_to(self.static_dir) or not target.is_file():
            return None
        return target


def make_server(
    model_files=(),
    model_dirs=(),
    host: str = "127.0.0.1",
    port: int = 0,
    static_dir: str | os.PathLike = STATIC_DIR,
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
    initial_upload: tuple[str, dict, dict | None] | None = None,
    measurement=None,
    verbose: bool = False,
    limits: ViewerLimits | None = None,
) -> ViewerServer:
    """Build (not start) a viewer server; ``port=0`` picks a free port.

    Parameters
    ----------
    model_files : iterable of path
        Model files to list first; the first one is opened when the page loads.
    model_dirs : iterable of path
        Folders whose ``*.kes.json`` files are listed too.
    initial_upload : (name, model_json, measurement_json), optional
        An already fitted model (``kesbrdf view meas.csv``) to open first.
    measurement : path, optional
        Measurement CSV shown with the first model file (hemisphere comparison);
        without it, the model's recorded input file is used when found unchanged.
    limits : ViewerLimits, optional
        Deadlines, connection and work budgets (default: :class:`ViewerLimits()`).
    """
    for f in model_files:
        load_model_json(f)  # fail early with the CLI's message
    store = ModelStore(model_dirs=[Path(d) for d in model_dirs], model_files=[Path(f) for f in model_files])
    entries = store.scan()
    if measurement is not None and model_files:
        from kesbrdf.io.measurement_csv import read_measurement

        entries[0].measurement = measurement_to_json(read_measurement(measurement))
    initial = None
    if initial_upload is not None:
        initial = store.add_upload(*initial_upload, pinned=True).id
    elif model_files:
        initial = entries[0].id
    elif entries:
        initial = entries[0].id
    return ViewerServer(
        (host, port), store, static_dir, max_upload_bytes, initial=initial, verbose=verbose, limits=limits
    )
