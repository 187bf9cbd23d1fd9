"""Local HTTP server of the web viewer: static bundle plus a small JSON API.

Standard library only (:mod:`http.server`).  The server binds to 127.0.0.1 by
default and serves

* the built viewer bundle from ``kesbrdf/viewer/static/`` (``GET /``, ``GET /assets/...``);
* ``GET /api/config``: ``{"initial": id or null, "max_upload_bytes": n, "version": ...}``;
* ``GET /api/models``: ``{"models": [{"id", "name", "kind", "has_measurement"}]}``;
* ``GET /api/model/<id>``: ``{"id", "name", "model": <the model file JSON, docs/formats.md>,
  "measurement": <see :func:`measurement_to_json`> or null}``;
* ``POST /api/fit?name=<file name>[&fallback=error|log]`` with the raw CSV bytes as body:
  reads it with :func:`kesbrdf.io.measurement_csv.read_measurement`, fits it with
  :func:`kesbrdf.fit` with its defaults (kind chosen from the data, as ``kesbrdf fit``
  with ``--no-compare``: the viewer draws the KES kinds, not ``fibre-prior``;
  ``fallback=error`` is ``--strict``, ``log`` the default), keeps the result in memory
  and answers like ``/api/model``.

Errors come back as ``{"error": "<one line>"}`` with a 4xx status (the same message
the CLI prints for the same input); the server keeps running.  Request bodies larger
than ``max_upload_bytes`` are refused with 413 before they are read.

Limits (``docs/formats.md``, "Viewer server limits"): a connection that sends nothing for
:data:`REQUEST_TIMEOUT_S` seconds is closed (408 if a body was pending); at most
:data:`MAX_CONNECTIONS` connections are served at once; an upload may have at most
:data:`MAX_FIT_CHANNELS` channels and :data:`MAX_FIT_VALUES` values (413 otherwise,
checked before fitting); a fitted answer larger than :data:`MAX_RESPONSE_BYTES` is
refused with 413; fitted uploads are kept in a cache of at most
:data:`MAX_UPLOADS_KEPT` entries and :data:`MAX_UPLOAD_CACHE_BYTES` bytes (oldest
dropped first; the model given on the command line is kept).  Only files
inside the static folder and the model files listed by ``/api/models`` are
reachable: every static path is resolved (symlinks included) and must stay inside
the static folder; models are addressed by id, never by path.
"""

from __future__ import annotations

import base64
import json
import os
import re
import tempfile
import threading
import urllib.parse
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from kesbrdf._atomic import write_bytes
from kesbrdf._version import __version__
from kesbrdf.errors import KesbrdfError, ModelError, where, validate_choice

__all__ = [
    "DEFAULT_MAX_UPLOAD_BYTES",
    "STATIC_DIR",
    "ModelEntry",
    "ModelStore",
    "ViewerServer",
    "make_server",
    "load_model_json",
    "fit_csv_bytes",
    "find_input_measurement",
    "measurement_to_json",
    "check_upload_work",
    "UploadTooLarge",
    "REQUEST_TIMEOUT_S",
    "MAX_CONNECTIONS",
    "MAX_FIT_CHANNELS",
    "MAX_FIT_VALUES",
    "MAX_RESPONSE_BYTES",
    "MAX_UPLOADS_KEPT",
    "MAX_UPLOAD_CACHE_BYTES",
]

#: Default upload limit: a dense 3° gonio CSV of four orientations is ~10 kB, a
#: hemispherical RGB scan a few MB.
DEFAULT_MAX_UPLOAD_BYTES = 5 * 1024 * 1024

#: Seconds a connection may stay silent (request line, headers, body, keep-alive idle).
REQUEST_TIMEOUT_S = 30.0

#: Connections served at once; more are closed at accept.
MAX_CONNECTIONS = 32

#: Channels one upload may have: the fit's time and memory grow with channels x grid
#: (a 300-channel upload took 35 s and 1.5 GB); 32 covers 400-700 nm at 10 nm.
MAX_FIT_CHANNELS = 32

#: Rows x channels one upload may have.
MAX_FIT_VALUES = 2_000_000

#: Largest JSON answer to one fit (model + measurement), bytes.
MAX_RESPONSE_BYTES = 32 * 1024 * 1024

#: Fitted uploads kept in memory (oldest dropped first) and their total JSON size.
MAX_UPLOADS_KEPT = 8
MAX_UPLOAD_CACHE_BYTES = 64 * 1024 * 1024

#: The built bundle shipped inside the package (``make viewer-bundle``).
STATIC_DIR = Path(__file__).resolve().parent / "static"

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
_SAFE_NAME = re.compile(r"[^A-Za-z0-9._ -]+")
_LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1"}
_MODEL_SUFFIXES = (".kes.json",)


# -- models -----------------------------------------------------------------------
def load_model_json(path: str | os.PathLike) -> dict:
    """Read and check a model file; return its JSON document unchanged.

    Uses :func:`kesbrdf.model.load` for the full check when it is available, so the
    error is the one the CLI gives for the same file.

    Raises
    ------
    ModelError
        Not JSON, not a kesbrdf model, or an unknown format version.
    """
    path = Path(path)
    try:
        from kesbrdf import model as model_module
    except ImportError:  # core model module not available: the format check below stands
        model_module = None
    if model_module is not None and hasattr(model_module, "load"):
        model_module.load(path)  # first, so that the error is the CLI's for the same file
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


def _array_json(a) -> dict:
    """Encode a float array like the model file does (docs/formats.md)."""
    import numpy as np

    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {
        "dtype": "<f8",
        "shape": list(a.shape),
        "data": base64.b64encode(a.tobytes()).decode("ascii"),
    }


def measurement_to_json(measurement) -> dict:
    """Viewer-friendly measurement: angles in radians, f_r in 1/sr, arrays as in model files."""
    import numpy as np

    psi = measurement.psi
    return {
        "channels": list(measurement.channels),
        "theta_i": _array_json(measurement.theta_i),
        "phi_i": _array_json(measurement.phi_i),
        "theta_r": _array_json(measurement.theta_r),
        "phi_r": _array_json(measurement.phi_r),
        "values": _array_json(measurement.values),
        "psi": None if psi is None else _array_json(np.where(np.isnan(psi), -1.0, psi)),
        "metadata": {str(k): str(v) for k, v in dict(measurement.metadata).items()},
        "notes": [str(n) for n in measurement.notes],
    }


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


def _safe_upload_name(name: str | None) -> str:
    base = os.path.basename((name or "upload.csv").replace("\\", "/")).strip()
    base = _SAFE_NAME.sub("_", base).lstrip(".") or "upload.csv"
    return base[:100]


def fit_csv_bytes(data: bytes, name: str = "upload.csv", fallback: str | None = None):
    """Read and fit an uploaded measurement CSV; return ``(model_json, measurement_json)``.

    The CSV is written to a private temporary folder under its (sanitised) upload
    name, so error messages read ``name.csv:12: ...`` exactly like
    ``kesbrdf fit name.csv`` would print them.
    """
    try:
        from kesbrdf.fitting import fit
        from kesbrdf.io.measurement_csv import read_measurement
    except ImportError as exc:  # pragma: no cover - core always ships these
        raise ModelError(f"fitting is not available in this installation: {exc}") from None
    safe = _safe_upload_name(name)
    with tempfile.TemporaryDirectory(prefix="kesbrdf-view-") as tmp:
        csv_path = Path(tmp) / safe
        write_bytes(csv_path, data)
        prefix = str(Path(tmp)) + os.sep
        try:
            measurement = read_measurement(csv_path)
            # the same entry point and defaults as `kesbrdf fit`; fallback=error is --strict.
            # compare=False: the viewer's shaders draw the KES kinds only, so the held-out
            # comparison with the woven-cloth prior (which may keep a fibre-prior model) is
            # skipped, as the demo does for its figures and renders (docs/models.md)
            model, _report = fit(measurement, strict=fallback == "error", compare=False)
            out = Path(tmp) / (Path(safe).stem + ".kes.json")
            model.save(out)
            model_doc = json.loads(out.read_text(encoding="utf-8"))
            info = model_doc.get("input")
            if isinstance(info, dict) and str(info.get("name", "")).startswith(prefix):
                info["name"] = safe  # the upload's name, not the temporary path
        except KesbrdfError as exc:
            # name the upload, not the private temporary folder
            message = str(exc).replace(prefix, "")
            try:
                renamed = type(exc)(message)
            except TypeError:  # a subclass with a different constructor
                renamed = KesbrdfError(message)
            raise renamed from None
    return model_doc, measurement_to_json(measurement)


class UploadTooLarge(KesbrdfError):
    """An upload would cost more work or memory than the server allows (HTTP 413)."""


def check_upload_work(data: bytes, name: str = "upload.csv") -> None:
    """Refuse an upload whose fit would be too costly, before fitting it.

    Parses the CSV (the reader's errors, named ``name:line``, come out unchanged) and
    checks channels and values against :data:`MAX_FIT_CHANNELS` and :data:`MAX_FIT_VALUES`.

    Raises
    ------
    UploadTooLarge
        Too many channels or values.
    KesbrdfError
        The CSV is malformed (same message as ``kesbrdf fit name``).
    """
    from kesbrdf.io.measurement_csv import parse_measurement
    from kesbrdf.io.text import decode_text

    measurement = parse_measurement(decode_text(data, name), source=name)
    n_channels = len(measurement.channels)
    if n_channels > MAX_FIT_CHANNELS:
        raise UploadTooLarge(
            f"{name}: expected at most {MAX_FIT_CHANNELS} channels for a fit in the viewer, got {n_channels}; "
            "fit it with 'kesbrdf fit' and open the model file"
        )
    values = len(measurement) * n_channels
    if values > MAX_FIT_VALUES:
        raise UploadTooLarge(
            f"{name}: expected at most {MAX_FIT_VALUES} values (rows x channels) for a fit in the viewer, got {values}"
        )


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
class _Handler(BaseHTTPRequestHandler):
    server: "ViewerServer"
    server_version = f"kesbrdf-view/{__version__}"
    protocol_version = "HTTP/1.1"
    #: socket timeout (StreamRequestHandler applies it): half-open requests do not stay open
    timeout = REQUEST_TIMEOUT_S

    def log_message(self, format, *args):  # noqa: A002 - signature from the base class
        if self.server.verbose:
            super().log_message(format, *args)

    # -- replies
    def _send(self, status: int, body: bytes, content_type: str, close: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        if close:
            self.send_header("Connection", "close")
            self.close_connection = True
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, doc, close: bool = False) -> None:
        self._send(status, json.dumps(doc).encode("utf-8"), "application/json", close=close)

    def _error(self, status: int, message: str, close: bool = False) -> None:
        self._json(status, {"error": " ".join(str(message).split())}, close=close)

    # -- routing
    def _foreign(self) -> bool:
        """True (and answered 403) for requests another web site makes through the user's browser.

        On a loopback address the Host header must name this machine (no DNS
        rebinding), and a request that carries an Origin must come from the viewer's
        own origin (no cross-site uploads).
        """
        host = (self.headers.get("Host") or "").strip().lower()
        hostname = urllib.parse.urlsplit(f"//{host}").hostname or ""
        if self.server.loopback and hostname not in _LOOPBACK_NAMES:
            self._error(403, f"expected a request to this machine, got Host {host!r}", close=True)
            return True
        origin = self.headers.get("Origin")
        if origin is not None and urllib.parse.urlsplit(origin).netloc.lower() != host:
            self._error(403, f"expected a request from the viewer's page, got Origin {origin!r}", close=True)
            return True
        return False

    def do_HEAD(self):  # noqa: N802 - http.server naming
        self.do_GET()

    def do_GET(self):  # noqa: N802
        if self._foreign():
            return None
        try:
            parsed = urllib.parse.urlsplit(self.path)
            path = parsed.path
            if path == "/api/config":
                return self._json(200, self.server.config())
            if path == "/api/models":
                entries = self.server.store.scan()
                return self._json(200, {"models": [_entry_summary(e) for e in entries]})
            if path.startswith("/api/model/"):
                return self._get_model(urllib.parse.unquote(path[len("/api/model/"):]))
            if path.startswith("/api/"):
                return self._error(404, f"unknown API endpoint {path}")
            return self._static(path)
        except Exception as exc:  # keep serving whatever happens
            return self._error(500, f"internal error: {type(exc).__name__}: {exc}")

    def do_POST(self):  # noqa: N802
        if self._foreign():
            return None
        try:
            parsed = urllib.parse.urlsplit(self.path)
            if parsed.path != "/api/fit":
                return self._error(404, f"unknown API endpoint {parsed.path}", close=True)
            return self._post_fit(urllib.parse.parse_qs(parsed.query))
        except Exception as exc:
            return self._error(500, f"internal error: {type(exc).__name__}: {exc}", close=True)

    def _get_model(self, entry_id: str) -> None:
        store = self.server.store
        entry = store.get(entry_id)
        if entry is None:
            store.scan()
            entry = store.get(entry_id)
        if entry is None:
            return self._error(404, f"no model with id {entry_id!r}; see /api/models")
        if entry.kind == "file":
            try:
                model = load_model_json(entry.path)
            except (KesbrdfError, OSError) as exc:
                msg = f"{exc.filename}: {exc.strerror}" if isinstance(exc, OSError) else str(exc)
                return self._error(422, msg)
            except Exception as exc:  # a loader bug must not look like a server crash: still the file's fault
                return self._error(422, f"{where(entry.path)}cannot load model file: {type(exc).__name__}: {exc}")
            measurement = entry.measurement or find_input_measurement(entry.path, model)
        else:
            model, measurement = entry.model, entry.measurement
        return self._json(
            200, {"id": entry.id, "name": entry.name, "model": model, "measurement": measurement}
        )

    def _post_fit(self, query: dict) -> None:
        limit = self.server.max_upload_bytes
        if "chunked" in self.headers.get("Transfer-Encoding", "").lower():
            return self._error(411, "expected a Content-Length, got a chunked upload", close=True)
        length_text = self.headers.get("Content-Length")
        if length_text is None:
            return self._error(411, "expected a Content-Length header on the upload", close=True)
        try:
            length = int(length_text)
            if length < 0:
                raise ValueError
        except ValueError:
            return self._error(400, f"expected a Content-Length, got {length_text!r}", close=True)
        if length > limit:
            # refuse without reading: the connection is closed after the reply
            return self._error(
                413, f"upload too large: {length} bytes, limit {limit} bytes", close=True
            )
        try:
            data = self.rfile.read(length)
        except TimeoutError:
            return self._error(408, f"upload incomplete after {self.timeout:g} s; expected {length} bytes", close=True)
        if len(data) != length:
            return self._error(400, f"upload incomplete: expected {length} bytes, got {len(data)}", close=True)
        name = _safe_upload_name((query.get("name") or ["upload.csv"])[0])
        fallback = (query.get("fallback") or [None])[0]
        try:
            if fallback is not None:
                validate_choice("fallback", fallback, ("error", "log"))
        except KesbrdfError as exc:
            return self._error(400, str(exc))
        try:
            check_upload_work(data, name)
        except UploadTooLarge as exc:
            return self._error(413, str(exc))
        except KesbrdfError as exc:
            return self._error(400, str(exc))
        try:
            model, measurement = fit_csv_bytes(data, name, fallback)
        except KesbrdfError as exc:
            return self._error(400, str(exc))
        except UnicodeDecodeError as exc:
            return self._error(400, f"{name}: expected UTF-8 text, got undecodable bytes ({exc.reason})")
        size = len(json.dumps(model)) + len(json.dumps(measurement))
        if size > MAX_RESPONSE_BYTES:
            return self._error(
                413, f"{name}: the fitted model would be {size} bytes of JSON, limit {MAX_RESPONSE_BYTES} bytes"
            )
        entry = self.server.store.add_upload(name, model, measurement, size=size)
        return self._json(
            200, {"id": entry.id, "name": entry.name, "model": model, "measurement": measurement}
        )

    def _static(self, url_path: str) -> None:
        target = self.server.resolve_static(url_path)
        if target is None:
            return self._error(404, f"not found: {url_path}")
        ctype = _CONTENT_TYPES.get(target.suffix.lower(), "application/octet-stream")
        return self._send(200, target.read_bytes(), ctype)


def _entry_summary(entry: ModelEntry) -> dict:
    return {
        "id": entry.id,
        "name": entry.name,
        "kind": entry.kind,
        "has_measurement": entry.measurement is not None,
    }


class ViewerServer(ThreadingHTTPServer):
    """The viewer's HTTP server; see the module docstring for the API."""

    daemon_threads = True
    allow_reuse_address = True
    max_connections = MAX_CONNECTIONS

    def __init__(
        self,
        address: tuple[str, int],
        store: ModelStore,
        static_dir: str | os.PathLike = STATIC_DIR,
        max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
        initial: str | None = None,
        verbose: bool = False,
    ) -> None:
        super().__init__(address, _Handler)
        self.store = store
        self.static_dir = Path(static_dir).resolve()
        self.max_upload_bytes = int(max_upload_bytes)
        self.initial = initial
        self.verbose = verbose
        host = str(self.server_address[0])
        self.loopback = host.startswith("127.") or host in ("::1", "localhost")
        self._active = threading.BoundedSemaphore(self.max_connections)

    def process_request(self, request, client_address):
        """Serve in a thread, or close at once when :data:`MAX_CONNECTIONS` are open."""
        if not self._active.acquire(blocking=False):
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._active.release()
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._active.release()

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
        (host, port), store, static_dir, max_upload_bytes, initial=initial, verbose=verbose
    )
