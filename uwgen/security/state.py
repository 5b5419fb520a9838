"""The state file of one side: sequence numbers reserved before use, and replay floors.

No nonce may ever repeat under one key, across crashes and power losses included. As
OSCORE's appendix B.1.1 describes, the sender never uses a number it has not first
*reserved* on disk: it writes "numbers below N are taken" (N = next + block) with an
fsync'd, atomically replaced file, and only then uses the numbers up to N. A sender
that restarts, however it stopped, continues at the last reserved N, so it can only
skip numbers, never repeat one.

The receiver side of the same file keeps, per sender, a *floor*: before it accepts a
number above the floor it raises the floor (by a block) on disk, so a restarted receiver
treats everything up to the floor as already seen and frames recorded before its
restart cannot be replayed to it. A clean stop writes the exact values.

The file names the key it belongs to (`key_id`), and so does its default path (next to
the key file, see `default_state_path`): a new key starts a new file at 0, and going back
to an old key finds that key's file again. A file that belongs to another key, or that is
unreadable or malformed, is refused (starting over under the same key could repeat
nonces). A missing file starts at 0, with a warning.
"""
from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

from uwgen.security.keys import SecurityError
from uwgen.security.wire import MAX_SENDER, MAX_SEQ

log = logging.getLogger("uwgen.security")

STATE_VERSION = 1
SEND_BLOCK = 256      # numbers reserved per write by a sender
RECV_BLOCK = 16       # how far a receiver raises its floor per write


def default_state_path(key_file: Path, network: str, side: str, key_id: str) -> Path:
    """`<key file>.<network>.<side>.<key id>.state`, next to the key file."""
    key_file = Path(key_file)
    return key_file.with_name(f"{key_file.name}.{network}.{side}.{key_id}.state")


class FileIO:
    """The file operations the state file needs; tests inject one that crashes."""

    def read(self, path: Path) -> bytes | None:
        try:
            return Path(path).read_bytes()
        except FileNotFoundError:
            return None

    def write_atomic(self, path: Path, data: bytes) -> None:
        """Write a temporary file, fsync it, rename it over `path`, fsync the folder: after a
        crash at any point the file holds either the old or the new content, whole."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


@dataclass
class State:
    key_id: str
    reserved: int = 0                      # the sender may use numbers below this
    floors: dict[int, int] = field(default_factory=dict)   # sender id -> replay floor

    def to_bytes(self) -> bytes:
        return json.dumps({"version": STATE_VERSION, "key_id": self.key_id, "reserved": self.reserved,
                           "floors": {str(k): v for k, v in sorted(self.floors.items())}},
                          sort_keys=True).encode() + b"\n"


def _whole(value, largest: int, what: str) -> int:
    """A whole number 0..largest from the file (JSON number or, for keys, its text); anything
    else (a fraction, 1e400, a 400-digit number, true) is a ValueError naming it."""
    if isinstance(value, str) and value.isascii() and value.isdigit() and len(value) <= 20:
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= largest:
        shown = repr(value) if len(repr(value)) <= 24 else repr(value)[:24] + "..."
        raise ValueError(f"{what} {shown} is not a whole number in 0..{largest}")
    return value


class StateFile:
    def __init__(self, path: Path, key_id: str, io: FileIO | None = None):
        self.path = Path(path)
        self.key_id = key_id
        self.io = io or FileIO()

    def load(self) -> State:
        try:
            data = self.io.read(self.path)
        except OSError as exc:
            raise SecurityError(f"cannot read security state file {self.path}: {exc}") from None
        if data is None:
            log.warning("no security state file %s: this side's sequence numbers start at 0 "
                        "(if it ever sent with this key before, give the network a new key)", self.path)
            return State(self.key_id)
        try:
            obj = json.loads(data)
            if obj.get("version") != STATE_VERSION:
                raise ValueError(f"version {obj.get('version')!r}")
            state = State(str(obj["key_id"]), _whole(obj["reserved"], MAX_SEQ + 1, "reserved"),
                          {_whole(k, MAX_SENDER, "sender id"): _whole(v, MAX_SEQ + 1, "floor")
                           for k, v in dict(obj["floors"]).items()})
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
            raise SecurityError(
                f"security state file {self.path} is damaged ({exc}); starting over could repeat "
                "nonces: restore it, or generate a new network key (uwgen keygen) and delete it") from None
        if state.key_id != self.key_id:
            raise SecurityError(
                f"security state file {self.path} belongs to another key ({state.key_id}, this key "
                f"is {self.key_id}): give each key its own state file (the default path does)")
        return state

    def save(self, state: State) -> None:
        try:
            self.io.write_atomic(self.path, state.to_bytes())
        except OSError as exc:
            raise SecurityError(f"cannot write security state file {self.path}: {exc}") from None


class SequenceSource:
    """The sender's numbers: never one that was not reserved on disk first."""

    def __init__(self, store: StateFile, state: State, block: int = SEND_BLOCK):
        self.store, self.state, self.block = store, state, block
        self.next = state.reserved          # past everything an earlier run may have used

    def take(self) -> int:
        if self.next >= self.state.reserved:
            reserved = self.state.reserved
            self.state.reserved = self.next + self.block
            try:
                self.store.save(self.state)
            except SecurityError:
                self.state.reserved = reserved
                raise
        seq = self.next
        self.next += 1
        return seq
