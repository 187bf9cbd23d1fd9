"""Where batch outputs live: a folder or an fsspec URL (``file://``, ``s3://`` ...).

:class:`Store` is rebuilt from its URL on every worker (it pickles as its URL and
storage options).  A step is computed in a *local* scratch folder and then committed:

* local file systems: the scratch folder is created next to its target,
  ``OUT/<fabric>/.tmp-<step>-<uuid>``, its files and folders are fsynced, and it is
  renamed onto ``OUT/<fabric>/<step>`` (one ``rename``: the step folder appears
  complete or not at all), then ``OUT/<fabric>`` is fsynced (the rename survives a
  power cut, and a committed folder never holds files whose data was not yet written);
* object stores (no rename): the files are uploaded first and ``manifest.json`` last,
  after any stale manifest was deleted.  A folder without a matching manifest counts
  as absent, so the manifest is the commit marker.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import uuid
from pathlib import Path

from kesbrdf._atomic import fsync_dir, fsync_file
from kesbrdf.errors import KesbrdfError

__all__ = ["Store", "is_url", "TMP_PREFIX"]

TMP_PREFIX = ".tmp-"
OLD_PREFIX = ".old-"


def is_url(text: str) -> bool:
    return "://" in str(text)


class Store:
    """A batch output root ``OUT``; paths below it are ``/``-separated relative names."""

    def __init__(self, root: str | os.PathLike, storage_options: dict | None = None):
        import fsspec

        root = str(root)
        self.url = root
        self.storage_options = dict(storage_options or {})
        self.fs, path = fsspec.core.url_to_fs(root, **self.storage_options)
        self.local = "file" in (self.fs.protocol if isinstance(self.fs.protocol, tuple) else (self.fs.protocol,))
        self.root = os.path.abspath(path) if self.local else path.rstrip("/")

    def __reduce__(self):
        return (Store, (self.url, self.storage_options))

    # -- names ---------------------------------------------------------------------
    def path(self, *parts: str) -> str:
        return "/".join([self.root, *[p.strip("/") for p in parts if p]])

    def display(self, *parts: str) -> str:
        """A path for humans and the summary: local path, or URL."""
        if self.local:
            return self.path(*parts)
        proto = self.fs.protocol[0] if isinstance(self.fs.protocol, tuple) else self.fs.protocol
        return f"{proto}://{self.path(*parts)}"

    # -- reading -------------------------------------------------------------------
    def read_bytes(self, *parts: str) -> bytes | None:
        """A stored file's bytes, or None when it is missing or (local) not a regular file."""
        try:
            if self.local:
                from kesbrdf.io.files import read_regular

                return read_regular(self.path(*parts))  # a FIFO in OUT is refused, never read
            with self.fs.open(self.path(*parts), "rb") as fh:
                return fh.read()
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
            return None
        except KesbrdfError:  # a FIFO, a device, a folder: as good as absent (the step is recomputed)
            return None

    def sha256(self, *parts: str) -> str | None:
        """sha256 of a stored file's bytes, or None when it is missing.

        Raises :class:`~kesbrdf.errors.FormatError` when a local path is not a regular
        file (a FIFO is refused, never opened).
        """
        h = hashlib.sha256()
        try:
            if self.local:
                from kesbrdf.io.files import open_regular

                fh = open_regular(self.path(*parts))
            else:
                fh = self.fs.open(self.path(*parts), "rb")
            with fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
        except (FileNotFoundError, NotADirectoryError):
            return None
        return h.hexdigest()

    def exists(self, *parts: str) -> bool:
        return self.fs.exists(self.path(*parts))

    def local_dir(self, *parts: str, cache: str | None = None) -> Path:
        """A local folder with the content of ``parts`` (the folder itself when local)."""
        if self.local:
            return Path(self.path(*parts))
        dest = Path(cache or tempfile.mkdtemp(prefix="kesbrdf-batch-in-")) / "/".join(parts)
        dest.mkdir(parents=True, exist_ok=True)
        self.fs.get(self.path(*parts) + "/", str(dest) + "/", recursive=True)
        return dest

    # -- writing -------------------------------------------------------------------
    def scratch(self, fabric: str, step: str) -> Path:
        """A fresh local folder to compute ``fabric``/``step`` in."""
        if self.local:
            parent = Path(self.path(fabric))
            parent.mkdir(parents=True, exist_ok=True)
            return Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{step}-", dir=parent))
        return Path(tempfile.mkdtemp(prefix=f"kesbrdf-batch-{step}-"))

    def commit(self, scratch: Path, fabric: str, step: str, manifest_name: str) -> bool:
        """Move a finished scratch folder (manifest included) to ``fabric/step``.

        Returns False when another attempt committed first (its result is kept).
        """
        target = self.path(fabric, step)
        if self.local:
            os.chmod(scratch, 0o777 & ~_umask())
            _fsync_tree(scratch)
            old = None
            if os.path.lexists(target):
                old = self.path(fabric, f"{OLD_PREFIX}{step}-{uuid.uuid4().hex[:8]}")
                try:
                    os.rename(target, old)
                except FileNotFoundError:
                    old = None
            try:
                os.rename(scratch, target)
            except OSError:  # a concurrent attempt of the same task won the race
                shutil.rmtree(scratch, ignore_errors=True)
                return False
            finally:
                if old:
                    shutil.rmtree(old, ignore_errors=True)
            fsync_dir(self.path(fabric))
            return True
        try:
            self.fs.rm(self.path(fabric, step, manifest_name))
        except FileNotFoundError:
            pass
        files = [p for p in sorted(scratch.rglob("*")) if p.is_file() and p.name != manifest_name]
        for p in files:
            self.fs.put_file(str(p), self.path(fabric, step, p.relative_to(scratch).as_posix()))
        self.fs.put_file(str(scratch / manifest_name), self.path(fabric, step, manifest_name))
        shutil.rmtree(scratch, ignore_errors=True)
        return True

    def discard(self, scratch: Path) -> None:
        shutil.rmtree(scratch, ignore_errors=True)

    def write_bytes(self, name: str, data: bytes) -> str:
        """Write one file at the root atomically (local: temp + rename)."""
        if self.local:
            from kesbrdf._atomic import write_bytes

            write_bytes(self.path(name), data)
        else:
            with self.fs.open(self.path(name), "wb") as fh:
                fh.write(data)
        return self.display(name)

    def sweep(self, fabrics) -> int:
        """Remove scratch folders left by killed attempts (call when no task runs)."""
        if not self.local:
            return 0
        n = 0
        for fabric in fabrics:
            d = Path(self.path(fabric))
            if not d.is_dir():
                continue
            for p in d.iterdir():
                if p.name.startswith((TMP_PREFIX, OLD_PREFIX)):
                    shutil.rmtree(p, ignore_errors=True)
                    n += 1
        return n


def _fsync_tree(folder: Path) -> None:
    """fsync every file below ``folder``, then every folder, deepest first."""
    dirs = [folder]
    for p in sorted(folder.rglob("*")):
        if p.is_dir() and not p.is_symlink():
            dirs.append(p)
        elif p.is_file() and not p.is_symlink():
            fsync_file(p)
    for d in reversed(dirs):
        fsync_dir(d)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
