"""The viewer server under hostile clients: slow heads and bodies, crowds, costly uploads.

Every client here talks to 127.0.0.1 only; every loop is bounded in count and time.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import socket
import threading
import time

import numpy as np
import pytest

from kesbrdf.viewer.server import ViewerLimits, make_server
from server_helpers import post_json

#: Longest any single wait of these tests lasts (s): far beyond every deadline under test.
WAIT_S = 20.0
#: Slack allowed past a deadline for the answer to arrive (s): scheduling on a loaded
#: 2-core machine, the server's timer, and (for fits) killing the child process.
SLACK_S = 1.5
#: Slow clients holding connections: more than the 32 slots the threaded server had.
SLOW_CLIENTS = 50
#: Concurrent GETs: the hostile test's wave size.
CROWD = 200
#: A normal request must be answered within this many seconds while slow clients wait.
ANSWER_S = 1.0


@pytest.fixture
def start(run_server):
    """Start servers with given limits; stop them after the test."""
    return lambda **limits: run_server(make_server(port=0, limits=ViewerLimits(**limits)))


def _get_config(srv, timeout=WAIT_S):
    host, port = srv.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=timeout)
    try:
        conn.request("GET", "/api/config")
        resp = conn.getresponse()
        return resp.status, json.loads(resp.read())
    finally:
        conn.close()


def _read_until_closed(sock: socket.socket, seconds: float) -> tuple[bool, bytes, float]:
    """(closed, received, seconds until closed) reading for at most ``seconds``."""
    t0 = time.monotonic()
    received = b""
    while (left := seconds - (time.monotonic() - t0)) > 0:
        sock.settimeout(left)
        try:
            chunk = sock.recv(65536)
        except (TimeoutError, socket.timeout):
            break
        except ConnectionResetError:
            return True, received, time.monotonic() - t0
        if not chunk:
            return True, received, time.monotonic() - t0
        received += chunk
    return False, received, time.monotonic() - t0


def test_a_normal_get_is_answered_within_1_s_while_50_slow_clients_hold_connections(start):
    srv = start(head_timeout_s=WAIT_S)  # the slow clients are not cut during the test
    address = srv.server_address[:2]
    slow = [socket.create_connection(address, timeout=WAIT_S) for _ in range(SLOW_CLIENTS)]
    stop = threading.Event()

    def trickle():  # one header line per client every 0.2 s, at most 50 rounds
        for k in range(50):
            for sock in slow:
                try:
                    sock.sendall(b"GET / HTTP/1.1\r\n" if k == 0 else f"X-Slow-{k}: 1\r\n".encode())
                except OSError:
                    pass
            if stop.wait(0.2):
                return

    sender = threading.Thread(target=trickle, daemon=True)
    sender.start()
    try:
        time.sleep(0.5)  # every slow client has connected and sent a line or two
        t0 = time.monotonic()
        status, doc = _get_config(srv, timeout=WAIT_S)
        elapsed = time.monotonic() - t0
        assert status == 200 and doc["version"]
        assert elapsed < ANSWER_S, f"answered after {elapsed:.2f} s"
    finally:
        stop.set()
        sender.join(WAIT_S)
        for sock in slow:
            sock.close()


async def _crowd_get(host: str, port: int, n: int) -> list[tuple[int, bool]]:
    """Open ``n`` connections at once, then send a GET on each; (status, body complete) per GET."""
    conns = await asyncio.gather(*(asyncio.open_connection(host, port) for _ in range(n)), return_exceptions=True)

    async def one(conn):
        if isinstance(conn, BaseException):
            return 0, False
        reader, writer = conn
        try:
            writer.write(f"GET /api/config HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
            await writer.drain()
            raw = await reader.read()  # until the server closes
        except OSError:
            return 0, False
        finally:
            writer.close()
        head, _, body = raw.partition(b"\r\n\r\n")
        if not head.startswith(b"HTTP/1.1 "):
            return 0, False
        length = next(
            (int(line.split(b":", 1)[1]) for line in head.split(b"\r\n") if line.lower().startswith(b"content-length:")),
            -1,
        )
        return int(head.split()[1]), length == len(body) and json.loads(body)["version"] is not None

    return await asyncio.wait_for(asyncio.gather(*(one(c) for c in conns)), WAIT_S)


def test_200_concurrent_gets_are_all_answered_in_full(start):
    srv = start()
    host, port = srv.server_address[:2]
    results = asyncio.run(_crowd_get(host, port, CROWD))
    answered = sum(status == 200 and complete for status, complete in results)
    assert answered == CROWD, f"{answered} of {CROWD} answered in full"
    assert _get_config(srv)[0] == 200


def _drip(srv, head: bytes, piece, deadline: float):
    """Send ``head``, then ``piece(k)`` every 0.1 s until the server closes or the deadline
    plus :data:`SLACK_S` passes; returns (bytes received, seconds from the first piece)."""
    with socket.create_connection(srv.server_address[:2], timeout=WAIT_S) as sock:
        sock.sendall(head)
        t0 = time.monotonic()
        received = b""
        for k in range(int((deadline + SLACK_S) / 0.1) + 1):
            try:
                sock.sendall(piece(k))
            except OSError:
                break
            closed, chunk, _ = _read_until_closed(sock, 0.1)
            received += chunk
            if closed:
                break
        return received, time.monotonic() - t0


def test_a_slow_request_head_is_cut_at_its_deadline(start):
    deadline = 1.0
    srv = start(head_timeout_s=deadline)
    # a header line every 0.1 s
    received, elapsed = _drip(srv, b"GET /api/config HTTP/1.1\r\n", lambda k: f"X-Slow-{k}: 1\r\n".encode(), deadline)
    assert received.startswith(b"HTTP/1.1 408"), received[:80]
    assert deadline - 0.1 <= elapsed < deadline + SLACK_S, f"cut after {elapsed:.2f} s"
    assert b"request head incomplete after 1 s" in received
    assert _get_config(srv)[0] == 200


def test_a_slow_body_is_cut_at_its_deadline(start):
    deadline = 1.0
    srv = start(body_timeout_s=deadline)
    # one body byte every 0.1 s
    head = b"POST /api/fit?name=slow.csv HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 1000\r\n\r\n"
    received, elapsed = _drip(srv, head, lambda k: b"0", deadline)
    assert received.startswith(b"HTTP/1.1 408"), received[:80]
    assert deadline - 0.1 <= elapsed < deadline + SLACK_S, f"cut after {elapsed:.2f} s"
    error = json.loads(received.partition(b"\r\n\r\n")[2])["error"]
    assert error.startswith("upload incomplete after 1 s") and "\n" not in error
    assert _get_config(srv)[0] == 200


def _scattered_csv(rows: int, seed: int = 7) -> bytes:
    """A scattered RGB measurement (general geometry): the costliest kind to fit per row."""
    rng = np.random.default_rng(seed)
    theta_i, theta_r = (np.degrees(np.arccos(rng.uniform(0.1, 1.0, rows))) for _ in range(2))
    phi_i, phi_r = (rng.uniform(0.0, 360.0, rows) for _ in range(2))
    lines = ["theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,R,G,B"]
    for k in range(rows):
        v = 0.1 + 0.05 * rng.random(3)
        lines.append(f"{theta_i[k]:.4f},{phi_i[k]:.4f},{theta_r[k]:.4f},{phi_r[k]:.4f},{v[0]:.5f},{v[1]:.5f},{v[2]:.5f}")
    return ("\n".join(lines) + "\n").encode()


_post = post_json


#: CPU and wall-clock budget of the fit under test (s).
FIT_BUDGET_S = 2.0
#: Rows of the costly upload: a scattered RGB fit of 3000 rows.  Its cost depends on the
#: machine: 300 rows took about 10 CPU-s where this test was written and 1.6 CPU-s on a
#: quiet CI machine (2026-12-03, which then finished under the budget and failed the
#: test); 2000 rows took 4.1 CPU-s there, so 3000 keep it at least 3x over the budget.
COSTLY_ROWS = 3000


def test_an_upload_over_the_cpu_budget_is_refused_within_the_budget(start):
    srv = start(fit_cpu_s=FIT_BUDGET_S, fit_wall_s=FIT_BUDGET_S)
    t0 = time.monotonic()
    status, doc = _post(srv, "/api/fit?name=costly.csv", _scattered_csv(COSTLY_ROWS))
    elapsed = time.monotonic() - t0
    assert status == 422, doc
    assert doc["error"].startswith("costly.csv: the fit did not finish within the viewer's work budget (2 CPU-s")
    assert "\n" not in doc["error"]
    assert elapsed < FIT_BUDGET_S + 2.0, f"refused after {elapsed:.2f} s"
    assert _get_config(srv)[0] == 200


def test_an_upload_over_the_rows_budget_of_its_kind_is_413_before_fitting(start):
    rows = 300
    srv = start(fit_values_by_kind={"scattered": rows * 3 - 1})
    t0 = time.monotonic()
    status, doc = _post(srv, "/api/fit?name=many.csv", _scattered_csv(rows))
    elapsed = time.monotonic() - t0
    assert status == 413, doc
    assert doc["error"].startswith(
        f"many.csv: expected at most {rows * 3 - 1} values (rows x channels) for a scattered fit in the viewer"
    )
    assert f"got {rows * 3} ({rows} rows x 3 channels)" in doc["error"]
    # no fit ran: parsing and choosing the kind take well under a second of the 10 CPU-s fit
    assert elapsed < FIT_BUDGET_S + 2.0, f"refused after {elapsed:.2f} s"


def test_uploads_beyond_the_fit_slots_and_queue_get_503_at_once(start):
    srv = start(fit_cpu_s=FIT_BUDGET_S, fit_wall_s=FIT_BUDGET_S, fit_workers=1, fit_queue=0)
    costly = _scattered_csv(COSTLY_ROWS)
    first: dict = {}
    worker = threading.Thread(target=lambda: first.update(answer=_post(srv, "/api/fit?name=a.csv", costly)))
    worker.start()
    try:
        time.sleep(0.5)  # the first fit holds the only slot
        t0 = time.monotonic()
        status, doc = _post(srv, "/api/fit?name=b.csv", costly)
        elapsed = time.monotonic() - t0
    finally:
        worker.join(WAIT_S)
    assert status == 503 and doc["error"].startswith("b.csv: the viewer is busy: 1 fit(s) running")
    assert elapsed < 1.0, f"refused after {elapsed:.2f} s"  # at once, not after the running fit
    assert first["answer"][0] == 422
