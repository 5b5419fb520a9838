"""The few file writes of the secure link (key files, the side lock), done so that a planted
symlink or a half-written file can never cost a key or its secrecy.

- `write_private(path, data)`: a new temporary file beside `path`, created with O_EXCL and
  O_NOFOLLOW (a leftover or planted `<path>.tmp`, symlink or not, is removed first, never
  followed), owner-only, written whole (every os.write result checked), fsync'd, then renamed
  over `path` (a rename replaces a symlink at `path`, it does not write through it), and the
  folder fsync'd: after a crash `path` holds the old or the new content, whole.
- `SideLock`: an exclusive, non-blocking lock (flock) on `<name>.lock`, held while a side runs,
  so a second copy of the same side on this machine is refused with a clear message.
"""
from __future__ import annotations

import errno
import fcntl
import os
from pathlib import Path

from uwgen.safefile import shown
from uwgen.security.errors import SecurityError

NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
CLOEXEC = getattr(os, "O_CLOEXEC", 0)


def write_all(fd: int, data: bytes, path: Path) -> None:
    """os.write until every byte is written; OSError if the disk takes none."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        if n <= 0:
            raise OSError(errno.EIO, f"wrote nothing to {path}")
        view = view[n:]


def write_private(path: Path, data: bytes, mode: int = 0o600) -> None:
    """Replace `path` by `data` atomically, owner-only, following no symlink (OSError if not)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW | CLOEXEC
    try:
        fd = os.open(tmp, flags, mode)
    except FileExistsError:
        os.unlink(tmp)                       # a leftover or planted file: removed, not followed
        fd = os.open(tmp, flags, mode)
    try:
        os.fchmod(fd, mode)                  # whatever the umask
        write_all(fd, data, tmp)
        os.fsync(fd)
    except BaseException:
        os.close(fd)
        os.unlink(tmp)
        raise
    os.close(fd)
    os.replace(tmp, path)
    dfd = os.open(path.parent, os.O_RDONLY | CLOEXEC)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


class SideLock:
    """An exclusive lock on `path` (created owner-only, never through a symlink) while held."""

    def __init__(self, path: Path, what: str):
        self.path, self.what = Path(path), what
        self._fd: int | None = None

    def acquire(self) -> "SideLock":
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | NOFOLLOW | CLOEXEC, 0o600)
        except OSError as exc:
            raise SecurityError(f"cannot open the lock file {shown(self.path)} of {self.what}: "
                                f"{exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EACCES):
                raise SecurityError(
                    f"{self.what} is already running on this machine (its lock {self.path} is "
                    "held): refusing to start a second copy of the same side") from None
            raise SecurityError(f"cannot lock {self.path}: {exc.strerror or exc}") from None
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)               # closing drops the flock; the file stays (harmless)
            self._fd = None

    def __enter__(self) -> "SideLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
