"""Opening input files: regular files only, and never an open that blocks.

A named pipe (FIFO), a character device (a terminal, ``/dev/zero``), a socket or a
folder given where a file is expected would make a reader block forever (a FIFO
with no writer) or read without end (``/dev/zero``).  Every reader of kesbrdf opens
its input through :func:`open_regular`, which refuses anything that is not a regular
file with one line, *before* reading from it (docs/formats.md, "Reading rules"):

* ``os.stat`` + :func:`stat.S_ISREG` on the path, then
* ``open`` with ``O_NONBLOCK`` (opening a FIFO never waits for a writer) and a second
  check with ``os.fstat`` on what was actually opened (the path may have been
  replaced between the two calls).

A missing or unreadable file still raises the usual :class:`OSError`
(``FileNotFoundError``, ``PermissionError``) from ``os.stat`` or ``os.open``.
"""

from __future__ import annotations

import hashlib
import os
import stat
from typing import BinaryIO

from kesbrdf.errors import FormatError, where

__all__ = ["open_regular", "read_regular", "file_kind", "sha256_file"]

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def file_kind(mode: int) -> str:
    """What a ``st_mode`` describes, for messages: ``"a named pipe (FIFO)"`` ...

    >>> import stat
    >>> file_kind(stat.S_IFIFO | 0o644), file_kind(stat.S_IFREG | 0o644)
    ('a named pipe (FIFO)', 'a regular file')
    """
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((name for test, name in _KINDS if test(mode)), "a special file")


def open_regular(path: str | os.PathLike) -> BinaryIO:
    """Open ``path`` for binary reading if it is a regular file, without ever blocking.

    Raises
    ------
    FormatError
        ``path`` is a FIFO, a device, a socket or a folder:
        ``"<path>: expected a regular file, got a named pipe (FIFO)"``.
    OSError
        ``path`` is missing or unreadable (as :func:`open` raises it).
    """
    name = os.fspath(path)
    mode = os.stat(name).st_mode
    if not stat.S_ISREG(mode):
        raise FormatError(f"{where(name)}expected a regular file, got {file_kind(mode)}")
    fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
                 | getattr(os, "O_BINARY", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):  # replaced between stat and open
            raise FormatError(f"{where(name)}expected a regular file, got {file_kind(mode)}")
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | os.PathLike) -> bytes:
    """The bytes of a regular file (:func:`open_regular`; drop-in for ``Path.read_bytes``)."""
    with open_regular(path) as fh:
        return fh.read()


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 of a regular file's bytes (hex), read in 1 MiB blocks; a FIFO, device or
    folder is refused (:func:`open_regular`), never opened."""
    digest = hashlib.sha256()
    with open_regular(path) as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
