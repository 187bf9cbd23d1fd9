"""Fixtures shared by the viewer server tests."""

from __future__ import annotations

import threading

import pytest

#: Longest teardown waits for a server thread to end (s); generous for a loaded machine.
JOIN_WAIT_S = 30.0


@pytest.fixture
def run_server():
    """``run_server(srv) -> srv``: serve ``srv`` on a thread; every server started this way
    is shut down and joined after the test."""
    started = []

    def run(srv):
        # short poll so shutdown() returns quickly
        thread = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)
        thread.start()
        started.append((srv, thread))
        return srv

    yield run
    for srv, thread in started:
        srv.shutdown()
        srv.server_close()
        thread.join(JOIN_WAIT_S)
