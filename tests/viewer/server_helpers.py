"""Plain HTTP helpers shared by the viewer server tests."""

from __future__ import annotations

import http.client
import json

#: Longest a request of these tests waits for the server (s); generous for a loaded machine.
WAIT_S = 20.0


def post_json(srv, path: str, body: bytes, timeout: float = WAIT_S):
    """POST ``body`` to ``path`` of ``srv``; (status, decoded JSON answer)."""
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=timeout)
    try:
        conn.request("POST", path, body=body, headers={"Content-Length": str(len(body))})
        resp = conn.getresponse()
        return resp.status, json.loads(resp.read())
    finally:
        conn.close()
