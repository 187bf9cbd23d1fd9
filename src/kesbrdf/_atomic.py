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

A write that fails in the system (disk full, read-only file system, name too long, a
file where a folder must be, permission denied, ...) raises
:class:`~kesbrdf.errors.OutputError`: one line naming the target and the cause in
words (:func:`output_error`).  Other errors raised inside the block pass unchanged.
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

from kesbrdf.errors import OutputError

__all__ = ["atomic_path", "write_text", "write_bytes", "remove_stale", "fsync_file", "fsync_dir",
           "output_error", "describe", "name_max", "STALE_LEGACY_SECONDS"]

#: Temporaries in the older naming (no process id: ``.<name>.<random>.part`` and the
#: animation encoder's ``.<stem>.partial<ext>``) are removed once they are this old.
STALE_LEGACY_SECONDS = 60.0

#: Longest file name (bytes) assumed when the file system does not say (POSIX NAME_MAX).
NAME_MAX = 255
#: Bytes a temporary's name adds to the target's: ``.`` ``.PID-RANDOM.part`` and a suffix.
_TMP_EXTRA = 48

#: The cause of a failed write, in words, by errno (any other code: the system's text).
_CAUSES = {
    errno.ENOSPC: "disk full (no space left on device)",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large for the file system",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied (operation not permitted)",
    errno.EIO: "input/output error (failing disk or lost network share)",
    errno.EMFILE: "too many open files",
    errno.ENFILE: "too many open files in the system",
    errno.ELOOP: "too many levels of symbolic links",
    errno.EBUSY: "file or device busy",
    errno.ETXTBSY: "file busy",
    errno.EISDIR: "expected a file, got an existing folder",
    errno.EXDEV: "temporary and target on different file systems",
}


def name_max(folder: Path) -> int:
    """Longest file name (bytes) in ``folder``'s nearest existing ancestor's file system."""
    for parent in (folder, *folder.parents):
        try:
            return int(os.pathconf(parent, "PC_NAME_MAX"))
        except (OSError, ValueError):
            continue
    return NAME_MAX


def describe(exc: OSError, path: str | os.PathLike) -> str:
    """``exc``'s cause in words, naming the part of ``path`` at fault where it can."""
    path = Path(path)
    code = exc.errno
    if code == errno.ENAMETOOLONG:
        limit = name_max(path.parent)
        longest = max(path.parts, key=lambda p: len(os.fsencode(p)))
        n = len(os.fsencode(longest))
        if n > limit:
            return f"file name too long ({n} bytes in {longest[:24]}..., at most {limit} on this file system)"
        return f"path too long ({len(os.fsencode(str(path)))} bytes)"
    if code in (errno.ENOTDIR, errno.EEXIST):
        for parent in reversed(path.parents):
            if parent.exists() and not parent.is_dir():
                return f"{parent} is a file, not a folder"
    if code == errno.ENOENT:
        for parent in reversed(path.parents):
            if not parent.exists():
                return f"folder {parent} does not exist"
    if code in _CAUSES:
        return _CAUSES[code]
    return (exc.strerror or str(exc) or type(exc).__name__).lower()


def output_error(exc: OSError, path: str | os.PathLike) -> OutputError:
    """The one-line :class:`OutputError` for ``exc``, raised while writing ``path``.

    >>> import errno
    >>> str(output_error(OSError(errno.ENOSPC, "No space left on device"), "out/m.kes.json"))
    'cannot write out/m.kes.json: disk full (no space left on device)'
    >>> str(output_error(OSError(errno.EROFS, "Read-only file system"), "/mnt/m.csv"))
    'cannot write /mnt/m.csv: read-only file system'
    """
    path = Path(path)
    return OutputError(f"cannot write {path}: {describe(exc, path)}", exc.errno)


def _about(exc: OSError, *paths: Path) -> bool:
    """Whether ``exc`` comes from writing one of ``paths`` (or names no file: a failed write)."""
    names = {os.fspath(p) for p in paths}
    given = [f for f in (exc.filename, exc.filename2) if f is not None]
    return not given or any(os.fspath(f) in names for f in given)


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders a failed write created (deepest first), if still empty."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def _tmp_name(path: Path) -> str:
    """The target's name as it appears in its temporaries (cut to fit the name limit)."""
    name = path.name
    limit = NAME_MAX - _TMP_EXTRA
    while len(os.fsencode(name)) > limit:
        name = name[:-1]
    return name


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
    name = re.escape(_tmp_name(path))
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
    try:
        if len(os.fsencode(path.name)) > name_max(path.parent):  # before any content is written
            raise OSError(errno.ENAMETOOLONG, os.strerror(errno.ENAMETOOLONG), str(path))
        is_dir = path.is_dir()
        created = [p for p in (path.parent, *path.parent.parents) if not p.exists()]  # deepest first
    except OSError as exc:  # a name or path too long, a file in the way, ...
        raise output_error(exc, path) from exc
    if is_dir:  # name the target, not the temporary file the rename would fail on
        raise IsADirectoryError(errno.EISDIR, "expected a file to write, got a directory", str(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale(path)
        suffix = ".part" + (path.suffix if keep_suffix else "")
        fd, tmp = tempfile.mkstemp(prefix=f".{_tmp_name(path)}.{os.getpid()}-", suffix=suffix, dir=path.parent)
    except OSError as exc:
        _remove_empty(created)
        raise output_error(exc, path) from exc
    tmp_path = Path(tmp)
    done = False
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
        done = True
    except OSError as exc:
        if not _about(exc, tmp_path, path):  # e.g. an input the block reads is missing
            raise
        raise output_error(exc, path) from exc
    finally:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        if not done:
            _remove_empty(created)


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
