"""Limits and work budgets of the viewer server (``kesbrdf view``; docs/formats.md, "Viewer server limits").

One frozen :class:`ViewerLimits` carries every number the server enforces, so the CLI
flags, the tests and the docs name the same fields.  The defaults were measured on a
2-core machine (docs/decisions.md, "Viewer server").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from kesbrdf.errors import KesbrdfError

__all__ = [
    "DEFAULT_MAX_UPLOAD_BYTES",
    "HEAD_TIMEOUT_S",
    "BODY_TIMEOUT_S",
    "KEEP_ALIVE_S",
    "MAX_CONNECTIONS",
    "LISTEN_BACKLOG",
    "WORKER_THREADS",
    "MAX_HEAD_BYTES",
    "FIT_CPU_S",
    "FIT_WALL_S",
    "FIT_WORKERS",
    "FIT_QUEUE",
    "MAX_FIT_CHANNELS",
    "MAX_FIT_VALUES",
    "MAX_FIT_VALUES_BY_KIND",
    "MAX_RESPONSE_BYTES",
    "MAX_UPLOADS_KEPT",
    "MAX_UPLOAD_CACHE_BYTES",
    "ViewerLimits",
]

#: Default upload limit: a dense 3° gonio CSV of four orientations is ~10 kB, a
#: hemispherical RGB scan a few MB.
DEFAULT_MAX_UPLOAD_BYTES = 5 * 1024 * 1024

#: Seconds from a connection's start (or the end of its last answer) to the end of the
#: next request's head (request line and headers): a whole-head deadline, not per recv.
HEAD_TIMEOUT_S = 10.0

#: Seconds from the end of a request's head to the end of its body (whole-body deadline):
#: 5 MB at 1 Mbit/s takes 40 s.
BODY_TIMEOUT_S = 60.0

#: Seconds an idle keep-alive connection stays open after an answer.
KEEP_ALIVE_S = 5.0

#: Connections open at once; further ones are closed at accept.  Slow connections cost
#: no thread (the server is asynchronous), only a file descriptor.
MAX_CONNECTIONS = 512

#: Listen backlog: connections the kernel queues before the server accepts them.
LISTEN_BACKLOG = 256

#: Threads that read model files and static files and encode answers (the queue in
#: front of them is bounded by MAX_CONNECTIONS: one request in flight per connection).
WORKER_THREADS = 8

#: Largest request head (request line + headers), bytes; larger ones get 400.
MAX_HEAD_BYTES = 64 * 1024

#: CPU seconds one fit of an upload may use (its child process is killed beyond).
#: The fits the viewer is for (paper protocol, dense gonio scans, a few thousand
#: scattered rows) take 0.2-45 CPU-s on the reference machine.
FIT_CPU_S = 60.0

#: Wall-clock seconds one fit may take (a loaded machine runs it at half speed).
FIT_WALL_S = 120.0

#: Fits running at once (each in its own process), and uploads waiting for one.
FIT_WORKERS = 1
FIT_QUEUE = 4

#: Channels one upload may have: the fit's time and memory grow with channels x grid
#: (a 300-channel upload took 35 s and 1.5 GB); 32 covers 400-700 nm at 10 nm.
MAX_FIT_CHANNELS = 32

#: Rows x channels one upload may have, whatever kind is fitted to it.
MAX_FIT_VALUES = 2_000_000

#: Rows x channels per fitted kind where a kind costs more per row than the general
#: limit allows: the scattered fit costs about 10 CPU-s + 4 CPU-ms per RGB row
#: (500 rows: 10 s, 8,000 rows: 44 s; 60,000 rows: 3.5 CPU-min), the grid kinds
#: (kes, kes-halfdiff) 2.5 CPU-s for 32,400 rows.
MAX_FIT_VALUES_BY_KIND = {"scattered": 24_000}

#: Largest JSON answer to one fit (model + measurement), bytes.
MAX_RESPONSE_BYTES = 32 * 1024 * 1024

#: Fitted uploads kept in memory (oldest dropped first) and their total JSON size.
MAX_UPLOADS_KEPT = 8
MAX_UPLOAD_CACHE_BYTES = 64 * 1024 * 1024


def _positive(name: str, value, integer: bool = False) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    if ok and integer:
        ok = float(value).is_integer()
    if not ok:
        kind = "a positive whole number" if integer else "a positive number"
        raise KesbrdfError(f"{name}: expected {kind}, got {value!r}")


@dataclass(frozen=True)
class ViewerLimits:
    """Every limit of one viewer server (defaults: the module constants).

    Times are seconds; ``fit_values_by_kind`` maps a fitter kind to its rows x channels
    budget (kinds not named have ``max_fit_values``).
    """

    head_timeout_s: float = HEAD_TIMEOUT_S
    body_timeout_s: float = BODY_TIMEOUT_S
    keep_alive_s: float = KEEP_ALIVE_S
    max_connections: int = MAX_CONNECTIONS
    backlog: int = LISTEN_BACKLOG
    worker_threads: int = WORKER_THREADS
    max_head_bytes: int = MAX_HEAD_BYTES
    fit_cpu_s: float = FIT_CPU_S
    fit_wall_s: float = FIT_WALL_S
    fit_workers: int = FIT_WORKERS
    fit_queue: int = FIT_QUEUE
    max_fit_channels: int = MAX_FIT_CHANNELS
    max_fit_values: int = MAX_FIT_VALUES
    fit_values_by_kind: dict = field(default_factory=lambda: dict(MAX_FIT_VALUES_BY_KIND))
    max_response_bytes: int = MAX_RESPONSE_BYTES

    def __post_init__(self) -> None:
        for name in ("head_timeout_s", "body_timeout_s", "keep_alive_s", "fit_cpu_s", "fit_wall_s"):
            _positive(name, getattr(self, name))
        for name in (
            "max_connections", "backlog", "worker_threads", "max_head_bytes", "fit_workers",
            "max_fit_channels", "max_fit_values", "max_response_bytes",
        ):
            _positive(name, getattr(self, name), integer=True)
        if not (isinstance(self.fit_queue, int) and self.fit_queue >= 0):
            raise KesbrdfError(f"fit_queue: expected a whole number >= 0, got {self.fit_queue!r}")
        for kind, budget in self.fit_values_by_kind.items():
            _positive(f"fit_values_by_kind[{kind!r}]", budget, integer=True)

    def values_budget(self, kind: str) -> int:
        """Rows x channels an upload fitted with ``kind`` may have."""
        return int(min(self.max_fit_values, self.fit_values_by_kind.get(kind, self.max_fit_values)))

    def to_json(self) -> dict:
        """The budgets a fit job needs (passed to its child process)."""
        return {
            "fit_cpu_s": self.fit_cpu_s,
            "max_fit_channels": self.max_fit_channels,
            "max_fit_values": self.max_fit_values,
            "fit_values_by_kind": dict(self.fit_values_by_kind),
            "max_response_bytes": self.max_response_bytes,
        }
