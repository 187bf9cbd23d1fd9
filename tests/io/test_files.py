"""Inputs that are not regular files are refused in one line, without blocking.

Every test runs the reader in a daemon thread and waits at most ``BLOCK_LIMIT_S``: on
the code before ``kesbrdf.io.files`` the readers called ``Path.read_bytes`` on a FIFO
with no writer, which blocks forever, so these tests failed by timeout there.
"""

from __future__ import annotations

import os
import socket
import threading

import pytest

from kesbrdf.errors import FormatError

#: A refusal is a stat and an open: milliseconds.  5 s is a generous bound on a loaded
#: 2-core machine and far below "forever".
BLOCK_LIMIT_S = 5.0

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs POSIX FIFOs")


def _call(fn, *args):
    """``fn(*args)`` in a thread; returns the exception it raised, or fails when it blocks."""
    box = {}

    def run():
        try:
            box["value"] = fn(*args)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(BLOCK_LIMIT_S)
    assert not t.is_alive(), f"{getattr(fn, '__name__', fn)} blocked on its input for {BLOCK_LIMIT_S} s"
    return box.get("error")


def _readers():
    from kesbrdf.measure.acquisition.images import read_image
    from kesbrdf.measure.acquisition.manifest import read_manifest
    from kesbrdf.io.curet import read_table
    from kesbrdf.io.measurement_csv import read_measurement
    from kesbrdf.io.model_file import load_model
    from kesbrdf.io.pairs_csv import read_pairs
    from kesbrdf.io.ply import read_ply
    from kesbrdf.io.tensor_file import read_tensor_file

    return {"measurement.csv": read_measurement, "manifest.csv": read_manifest, "table.txt": read_table,
            "model.kes.json": load_model, "pairs.csv": read_pairs, "mesh.ply": read_ply,
            "frame.png": read_image, "model.bsdf": read_tensor_file}


@pytest.mark.parametrize("name", sorted(_readers()))
def test_every_reader_refuses_a_fifo_in_one_line(tmp_path, name):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    exc = _call(_readers()[name], fifo)
    assert isinstance(exc, FormatError), repr(exc)
    assert str(exc) == f"{fifo}: expected a regular file, got a named pipe (FIFO)"


def test_folder_device_and_socket_are_refused_and_regular_files_read(tmp_path):
    from kesbrdf.io.files import open_regular, read_regular

    sock_path = tmp_path / "s.sock"
    sock = socket.socket(socket.AF_UNIX)
    try:
        sock.bind(str(sock_path))
        cases = {tmp_path: "a directory", sock_path: "a socket"}
        if os.path.exists("/dev/zero"):  # reading it would never end
            cases["/dev/zero"] = "a character device"
        for path, kind in cases.items():
            exc = _call(read_regular, path)
            assert isinstance(exc, FormatError) and str(exc) == f"{path}: expected a regular file, got {kind}"
    finally:
        sock.close()
    f = tmp_path / "x.csv"
    f.write_bytes(b"a,b\n")
    link = tmp_path / "link.csv"
    link.symlink_to(f)
    assert read_regular(link) == b"a,b\n"  # a symlink to a regular file is a regular file
    with pytest.raises(FileNotFoundError):
        open_regular(tmp_path / "missing.csv")
