"""Atomic file output: write to a temporary file beside the target, then rename.

A crash or an error mid-write never leaves a half-written output behind: the target
is either the old file or the complete new one (``os.replace`` is atomic on POSIX
and Windows within one folder).  The temporary file is fsynced before the rename and
the folder after it, so after a power cut the target is never an empty or partial file
that a later run would take as finished.

Temporary files are named ``.<target name>.<pid>-<random>.part[<suffix>]``, hidden
beside the target.  They are removed

* when the write fails for any reason (an exception, ``KeyboardInterrupt``), and
* when a later write of the same target starts (:func:`remove_stale`): a process
  killed by SIGKILL or a power cut cannot clean up, so the next writer removes the
  temporaries whose writing process is gone.  Temporaries of a process that is still
  running (a concurrent writer) are left alone.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import tempfile
import time
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path", "write_text", "write_bytes", "remove_stale", "fsync_file", "fsync_dir",
           "STALE_LEGACY_SECONDS"]

#: Temporaries in the older naming (no process id: ``.<name>.<random>.part`` and the
#: animation encoder's ``.<stem>.partial<ext>``) are removed once they are this old.
STALE_LEGACY_SECONDS = 60.0


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    except OSError:  # pragma: no cover - platforms without signal 0
        return True
    return True


def remove_stale(path: str | os.PathLike) -> list[Path]:
    """Remove temporaries of ``path`` left by writers that died; return what was removed.

    A temporary is stale when the process id in its name is not running, or, for
    the older names without a process id, when it is older than
    :data:`STALE_LEGACY_SECONDS`.  Errors while removing (a file that vanished,
    no permission) are ignored: cleaning up never makes a write fail.
    """
    path = Path(path)
    folder = path.parent
    name = re.escape(path.name)
    stem, ext = re.escape(path.stem), re.escape(path.suffix)
    current = re.compile(rf"^\.{name}\.(\d+)-[A-Za-z0-9_]+\.part(\.[^./]*)?$")
    legacy = re.compile(rf"^(\.{name}\.[A-Za-z0-9_]+\.part|\.{stem}\.partial{ext})$")
    removed: list[Path] = []
    try:
        candidates = [p for p in folder.iterdir() if p.name.startswith(".")]
    except OSError:
        return removed
    now = time.time()
    for p in candidates:
        m = current.match(p.name)
        try:
            if m is not None:
                stale = not _pid_alive(int(m.group(1)))
            elif legacy.match(p.name):
                stale = now - p.stat().st_mtime > STALE_LEGACY_SECONDS
            else:
                continue
            if stale and p.is_file():
                p.unlink()
                removed.append(p)
        except OSError:
            continue
    return removed


def fsync_file(path: str | os.PathLike) -> None:
    """Flush a file's data to the disk (``fsync``); errors (EIO, a full disk) propagate."""
    # POSIX fsyncs through any descriptor (so read-only files work too); Windows needs write access
    fd = os.open(path, (os.O_RDONLY if os.name == "posix" else os.O_RDWR) | getattr(os, "O_BINARY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(folder: str | os.PathLike) -> None:
    """Flush a folder's entries (a rename into it) to the disk.

    Best effort: platforms and file systems that cannot open or fsync a folder
    (Windows, some network file systems) are skipped silently.
    """
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``path`` on success.

    Parameters
    ----------
    path : path-like
        The target.  Its folder is created if missing.
    keep_suffix : bool
        End the temporary's name with the target's suffix (``.part.mp4``), for writers
        that pick the format from the file name.

    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "x.txt") as tmp:
    ...     _ = tmp.write_text("hi")
    >>> (d / "x.txt").read_text(), sorted(p.name for p in d.iterdir())
    ('hi', ['x.txt'])
    """
    path = Path(path)
    if path.is_dir():  # name the target, not the temporary file the rename would fail on
        raise IsADirectoryError(errno.EISDIR, "expected a file to write, got a directory", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(path)
    suffix = ".part" + (path.suffix if keep_suffix else "")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-", suffix=suffix, dir=path.parent)
    tmp_path = Path(tmp)
    try:
        os.close(fd)
        yield tmp_path
        # mkstemp creates 0600 files; give the output the usual 0666 & ~umask
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        fsync_file(tmp_path)  # the bytes are on disk before the name points at them
        os.replace(tmp_path, path)
        fsync_dir(path.parent)  # and the rename itself survives a power cut
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)
