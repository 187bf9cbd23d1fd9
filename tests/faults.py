"""Fault injection for write-error tests: make one folder fail like a full disk, a
read-only file system, a denied permission or a failing device.

No privileges or special mounts needed (tests run as root in CI, where permission bits
do not stop writes, and a tmpfs cannot be mounted): :func:`failing_writes` patches the
calls every kesbrdf write ends in — ``os.open`` (``tempfile.mkstemp``), ``os.mkdir``,
``io.open``/``builtins.open`` (``Path.write_text``, Pillow, tifffile, numpy) and
``os.replace`` — for paths inside one folder only, so reading inputs elsewhere works.

``at`` says where the failure strikes, as the real file systems do:

* ``"create"``: creating a file or folder fails (``EROFS``, ``EACCES``, ``EDQUOT``);
* ``"write"``: files open, the first ``after_bytes`` bytes are written, then every
  write fails (``ENOSPC``, ``EDQUOT``, ``EFBIG``, ``EIO``), so a half file exists on disk
  until the writer removes it;
* ``"rename"``: everything is written and the final rename fails (``EIO``, ``EROFS``
  remounted mid-run).

The raised errors look like the kernel's: ``OSError(code, strerror)``, with the file
name where the real call gives one (``open``, ``mkdir``, ``rename``) and none for
``write``.
"""

from __future__ import annotations

import builtins
import errno
import io
import os
from pathlib import Path

__all__ = ["failing_writes", "listing", "WRITE_MODES"]

#: ``open`` modes that create or change a file.
WRITE_MODES = set("wax+")
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND


def listing(folder: Path) -> list[str]:
    """Every path below ``folder`` (hidden temporaries included), sorted, relative."""
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))


def _inside(path, folder: str) -> bool:
    if isinstance(path, int):  # a file descriptor
        return False
    try:
        p = os.path.abspath(os.fsdecode(path))
    except (TypeError, ValueError):
        return False
    return p == folder or p.startswith(folder + os.sep)


class _FailingFile:
    """A file object whose writes fail with ``code`` once ``budget`` bytes were written."""

    def __init__(self, fh, budget: int, code: int):
        self._fh, self._budget, self._code = fh, budget, code

    def write(self, data):
        n = min(len(data), max(self._budget, 0))
        if n:
            self._fh.write(data[:n])
            self._fh.flush()
            self._budget -= n
        if n < len(data):
            raise OSError(self._code, os.strerror(self._code))
        return len(data)

    def writelines(self, lines):
        for line in lines:
            self.write(line)

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._fh.close()
        return False

    def __iter__(self):
        return iter(self._fh)


def failing_writes(monkeypatch, folder, code: int, at: str = "write", after_bytes: int = 64) -> None:
    """From now on (until ``monkeypatch`` undoes it), writes inside ``folder`` fail with ``code``.

    Parameters
    ----------
    monkeypatch : pytest.MonkeyPatch
    folder : path-like
        Only paths inside it (or it) fail.
    code : int
        The errno, e.g. ``errno.ENOSPC``.
    at : {"create", "write", "rename"}
        Where the failure strikes (module docstring).
    after_bytes : int
        With ``at="write"``: bytes each file accepts before failing.
    """
    if at not in ("create", "write", "rename"):
        raise ValueError(f"at: expected create, write or rename, got {at!r}")
    folder = os.path.abspath(os.fspath(folder))
    real_open, real_os_open, real_mkdir, real_replace = io.open, os.open, os.mkdir, os.replace

    def fail(path):
        raise OSError(code, os.strerror(code), os.fsdecode(path))

    def fake_open(file, mode="r", *args, **kwargs):
        writing = bool(WRITE_MODES & set(mode))
        if writing and _inside(file, folder):
            if at == "create":
                fail(file)
            if at == "write":
                return _FailingFile(real_open(file, mode, *args, **kwargs), after_bytes, code)
        return real_open(file, mode, *args, **kwargs)

    def fake_os_open(path, flags, *args, **kwargs):
        if at == "create" and flags & _WRITE_FLAGS and _inside(path, folder):
            fail(path)
        return real_os_open(path, flags, *args, **kwargs)

    def fake_mkdir(path, *args, **kwargs):
        if at == "create" and _inside(path, folder):
            fail(path)
        return real_mkdir(path, *args, **kwargs)

    def fake_replace(src, dst, *args, **kwargs):
        if at == "rename" and _inside(dst, folder):
            raise OSError(code, os.strerror(code), os.fsdecode(src), None, os.fsdecode(dst))
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(io, "open", fake_open)
    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(os, "open", fake_os_open)
    monkeypatch.setattr(os, "mkdir", fake_mkdir)
    monkeypatch.setattr(os, "replace", fake_replace)


#: errno -> (where it strikes, words the one-line error must contain)
CASES = {
    "ENOSPC": (errno.ENOSPC, "write", "disk full"),
    "EDQUOT": (errno.EDQUOT, "write", "disk quota exceeded"),
    "EFBIG": (errno.EFBIG, "write", "file too large"),
    "EIO": (errno.EIO, "rename", "input/output error"),
    "EROFS": (errno.EROFS, "create", "read-only file system"),
    "EACCES": (errno.EACCES, "create", "permission denied"),
}
