"""The demo's network key: found or created, never committed, one demo at a time per key.

The demo manifest names `keys/demo.key` (relative to its folder; git-ignored). `uwgen demo`
uses that file and creates it when missing, with uwgen's keygen code (owner-only, 0600).
When that folder cannot be written (a read-only checkout), the key is
`<uwgen cache>/demo/keys/demo.key` instead, created there when missing, as the demo's
output falls back to the cache. Both bridges get the key with `--key-file`.

The bridges keep no state on disk (a fresh epoch, so a fresh working key, per start), but
each holds a lock next to the key while it runs, so a second copy of a side is refused. Two
demos on one key would have their second pair of bridges refused: a demo holds an exclusive
lock on `<key>.lock` while its bridges run, and a second demo that finds the key in use makes
a key of its own for that run only, in its output folder.
"""
from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from uwgen import yamltext
from uwgen.security.keys import read_key_file, write_key_file


@dataclass(frozen=True)
class DemoKey:
    path: Path
    created: bool          # created by this run
    note: str = ""         # why this key and not the manifest's, if so

    def bridge_args(self) -> list[str]:
        return ["--key-file", str(self.path)]

    def describe(self) -> str:
        how = "created now (owner-only)" if self.created else "existing"
        return (f"network key: {self.path} ({how}{'; ' + self.note if self.note else ''}); both "
                "bridges get it with --key-file, their lock files stay next to it")


def manifest_key_file(manifest: Path) -> Path | None:
    """The manifest's `security: {key_file: ...}`, relative to its folder (None: no security).
    The manifest was loaded by `uwgen build` already; this only needs the one key."""
    data = yamltext.safe_load(Path(manifest).read_text(encoding="utf-8")) or {}
    security = data.get("security") if isinstance(data, dict) else None
    key_file = security.get("key_file") if isinstance(security, dict) else None
    if not key_file:
        return None
    path = Path(key_file).expanduser()
    return path if path.is_absolute() else Path(manifest).parent / path


def _writable(folder: Path) -> bool:
    """Whether `folder` can be written, or created in its nearest existing ancestor."""
    folder = Path(folder)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return os.access(folder, os.W_OK | os.X_OK)


def _cache_key(name: str) -> Path:
    from uwgen.typesupport import cache_root
    return cache_root() / "demo" / "keys" / name


def _ensure(path: Path) -> bool:
    """Create the key at `path` when missing; check it either way (SecurityError if it is not
    a usable key: not owner-only, malformed). Returns whether it was created."""
    created = False
    if not path.exists():
        write_key_file(path)
        created = True
    read_key_file(path)
    return created


@contextmanager
def demo_key(manifest: Path, out: Path, key_file: Path | None = None) -> Iterator[DemoKey | None]:
    """The key the demo's bridges use (None when the manifest protects nothing): `key_file`
    if given (`uwgen demo --key-file`), else the manifest's; locked for this demo while the
    context is open. Raises SecurityError or OSError with the reason."""
    wanted = manifest_key_file(manifest)
    if wanted is None:
        yield None
        return
    if key_file is not None:
        wanted = Path(key_file).expanduser()
    path, note = wanted, ""
    if key_file is None and not _writable(wanted.parent):
        path, note = _cache_key(wanted.name), f"{wanted.parent} is read-only"
    created = _ensure(path)
    with open(path.with_name(path.name + ".lock"), "a", encoding="utf-8") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield _run_only_key(out, path)
            return
        try:
            yield DemoKey(path, created, note)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _run_only_key(out: Path, busy: Path) -> DemoKey:
    """A new key for this run alone (another demo holds `busy`), in its own folder."""
    folder = Path(out) / "keys"
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("*.state"):
        old.unlink()             # left by builds that kept state files (none is read now)
    path = folder / busy.name
    write_key_file(path, force=True)
    return DemoKey(path, True, f"for this run only: another demo is using {busy}")
