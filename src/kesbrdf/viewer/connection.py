"""One HTTP/1.1 connection of the viewer server: uvicorn's h11 protocol plus two limits.

uvicorn closes idle keep-alive connections, but a client that trickles a request head
(one header line every few seconds) is never timed out by it.  :class:`ViewerH11Protocol`
adds

* a **head deadline**: from the connection's start, and from the end of each answer,
  the next request's head must be complete within ``head_timeout_s`` (whole head, not
  per read); otherwise the connection gets a one-line 408 (when part of a head arrived)
  and is closed;
* a **connection cap**: beyond ``max_connections`` open connections a new one is
  closed at accept, before anything is read.

The body's deadline is the application's (:mod:`kesbrdf.viewer.server`): it knows the
request and can answer 408 in its own JSON form.
"""

from __future__ import annotations

import json

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from kesbrdf.viewer.limits import ViewerLimits

__all__ = ["ViewerH11Protocol", "protocol_class"]


class ViewerH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a whole-head deadline and a connection cap."""

    limits: ViewerLimits = ViewerLimits()
    server_name: str = "kesbrdf-view"

    def connection_made(self, transport) -> None:  # noqa: D102 - asyncio.Protocol
        self._head_timer = None
        super().connection_made(transport)
        if len(self.connections) > self.limits.max_connections:
            transport.close()  # over the cap: closed at accept, nothing read or answered
            return
        self._arm_head_deadline()

    def connection_lost(self, exc) -> None:  # noqa: D102
        self._disarm_head_deadline()
        super().connection_lost(exc)

    def on_response_complete(self) -> None:  # noqa: D102
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm_head_deadline()  # the next request's head has its own deadline

    def _arm_head_deadline(self) -> None:
        self._disarm_head_deadline()
        self._head_timer = self.loop.call_later(self.limits.head_timeout_s, self._head_deadline_passed)

    def _disarm_head_deadline(self) -> None:
        if getattr(self, "_head_timer", None) is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_deadline_passed(self) -> None:
        self._head_timer = None
        if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
            return  # closed, or the head is complete (the body has the application's deadline)
        partial, _closed = self.conn.trailing_data
        if partial and self.conn.our_state is h11.IDLE:
            body = json.dumps(
                {"error": f"request head incomplete after {self.limits.head_timeout_s:g} s (kesbrdf view --head-timeout-s)"}
            ).encode()
            self.transport.write(
                b"HTTP/1.1 408 Request Timeout\r\n"
                b"Content-Type: application/json\r\n"
                + f"Content-Length: {len(body)}\r\nServer: {self.server_name}\r\n".encode()
                + b"Connection: close\r\n\r\n"
                + body
            )
        self.transport.close()


def protocol_class(limits: ViewerLimits, server_name: str) -> type[ViewerH11Protocol]:
    """A :class:`ViewerH11Protocol` subclass bound to ``limits`` (uvicorn builds one per connection)."""
    return type("BoundViewerH11Protocol", (ViewerH11Protocol,), {"limits": limits, "server_name": server_name})
