"""Reading a file a user names (a manifest, a key file, a scenario, an interface definition)
without trusting what the name leads to.

`Path.read_text` reads to the end before anything can be checked: a name that leads to
/dev/zero or /dev/urandom never ends (and cannot be interrupted: the read is one C call),
a FIFO with no writer blocks forever, a symlink loop ends in RuntimeError from
`Path.resolve`, a 5 000-character name in OSError. `read_bytes` instead:

1. opens the name once, non-blocking (a FIFO opens at once) and close-on-exec; symlinks are
   followed by the kernel (a key file may be a link into a secrets folder), a loop is ELOOP;
2. looks at what it opened (fstat on the open descriptor, so nothing can be swapped in
   between): only a regular file is read, and only if it is at most `limit` bytes;
3. reads at most `limit + 1` bytes (a file that grows while it is read is refused too).

Every refusal is an `UnreadableFile` whose message names the file (a long name shortened)
and says what it is instead. The callers turn it into their own error (ManifestError,
SecurityError, DefinitionError). `check` lets a caller look at the stat result before any
byte is read (the key file's owner-only mode).

    data = read_bytes(path, "manifest", MANIFEST_LIMIT)
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Callable

CLOEXEC = getattr(os, "O_CLOEXEC", 0)
NONBLOCK = getattr(os, "O_NONBLOCK", 0)
SHOWN_PATH = 120     # a longer name is cut in messages (a 5 000-character --key-file)

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISSOCK, "a socket"))


class UnreadableFile(Exception):
    """A file that is not read, and why; str() names the file."""

    def __init__(self, path: Path | str, message: str, missing: bool = False,
                 line: int = 0, column: int = 0, reason: str = ""):
        self.path = Path(path)
        self.message = message
        self.missing = missing       # nothing there at all (a caller may say how to make one)
        self.line, self.column = line, column   # where in the text, for a decoding problem
        self.reason = reason or message          # the message without the file's name
        super().__init__(message)


def shown(path: Path | str) -> str:
    """`path` as a message shows it: cut short past SHOWN_PATH characters."""
    text = str(path)
    if len(text) <= SHOWN_PATH:
        return text
    return f"{text[:SHOWN_PATH // 2]}...{text[-SHOWN_PATH // 4:]} (a name of {len(text)} characters)"


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _size(n: int) -> str:
    return f"{n // 1024 ** 2} MiB" if n >= 1024 ** 2 and n % 1024 ** 2 == 0 else (
        f"{n // 1024} KiB" if n >= 1024 and n % 1024 == 0 else f"{n} bytes")


def _target(path: Path) -> str:
    """' (a symlink to X)' when `path` is a symlink, else ''."""
    try:
        if os.path.islink(path):
            return f" (a symlink to {shown(os.path.realpath(path))})"
    except (OSError, ValueError):
        pass
    return ""


def _open_error(path: Path, what: str, exc: OSError) -> UnreadableFile:
    name = shown(path)
    reasons = {
        errno.ENOENT: "not found",
        errno.ELOOP: "is a symlink loop (or a chain of more than 40 symlinks)",
        errno.ENAMETOOLONG: "has a name too long for this system",
        errno.EACCES: "cannot be read: permission denied",
        errno.ENOTDIR: "not found (a part of its path is not a folder)",
        errno.EISDIR: "is a folder, not a file",
        errno.ENXIO: "is a socket or a device without a reader: not a regular file",
    }
    reason = reasons.get(exc.errno, f"cannot be opened: {exc.strerror or exc}")
    return UnreadableFile(path, f"{what} {name} {reason}",
                          missing=exc.errno in (errno.ENOENT, errno.ENOTDIR))


def problem(path: Path | str, what: str) -> str | None:
    """Why `path` could not be read as a regular file (a loop, a name too long, a device, a
    folder, a FIFO), or None if it is one or is not there (a caller may say more about a
    missing file). Looks only: nothing is opened, so nothing can block."""
    path = Path(path)
    try:
        info = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as exc:
        return str(_open_error(path, what, exc))
    except ValueError:
        return f"{what} {shown(path)!r} has a NUL character in its name"
    if not stat.S_ISREG(info.st_mode):
        return f"{what} {shown(path)}{_target(path)} is {_kind(info.st_mode)}: only a regular file is read"
    return None


def read_bytes(path: Path | str, what: str, limit: int,
               check: Callable[[os.stat_result], None] | None = None) -> bytes:
    """The bytes of the regular file `path`, at most `limit` of them; UnreadableFile if not.

    `what` names the file in messages ("manifest", "key file"); `check(stat)` runs on the
    opened file before any byte is read and may raise its own error."""
    path = Path(path)
    if "\x00" in str(path):
        raise UnreadableFile(path, f"{what} {shown(path)!r} has a NUL character in its name")
    try:
        fd = os.open(path, os.O_RDONLY | NONBLOCK | CLOEXEC)
    except OSError as exc:
        raise _open_error(path, what, exc) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile(path, f"{what} {shown(path)}{_target(path)} is {_kind(info.st_mode)}: "
                                       "only a regular file is read")
        if info.st_size > limit:
            raise UnreadableFile(path, f"{what} {shown(path)} is {info.st_size} bytes long: "
                                       f"uwgen reads at most {_size(limit)}")
        if check is not None:
            check(info)
        chunks, total = [], 0
        while total <= limit:
            try:
                chunk = os.read(fd, limit + 1 - total)
            except OSError as exc:
                raise UnreadableFile(path, f"{what} {shown(path)} cannot be read: {exc.strerror or exc}") from None
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        if total > limit:
            raise UnreadableFile(path, f"{what} {shown(path)} grew past {_size(limit)} while being read")
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_text(path: Path | str, what: str, limit: int, encoding: str = "utf-8") -> str:
    """`read_bytes` decoded; text that is not `encoding` is an UnreadableFile saying where."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        reason = (f"not valid {'UTF-8' if encoding == 'utf-8' else encoding} text "
                  f"(byte 0x{data[exc.start]:02x})")
        raise UnreadableFile(path, f"{what} {shown(path)}:{line}:{column}: {reason}",
                             line=line, column=column, reason=reason) from None
