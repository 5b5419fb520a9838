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

Hygiene (issue 17, item 5): the file records the sender id it was written for, and one
written for another id is refused (ids renumbered under one key would repeat nonces); every
number is checked to be an integer in 0..2^43-1 (a float, a bool, `1e999` or a number past
the sequence space is refused with the field's path); the file is written through
`files.write_private` (O_EXCL | O_NOFOLLOW temporary file, every write checked); and while a
guard uses it, `<state file>.lock` is held (`lock()`), so a second copy of the same side on
this machine is refused before it sends anything.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

from uwgen.security.errors import SecurityError
from uwgen.security.files import SideLock, write_private
from uwgen.security.wire import MAX_SENDER, MAX_SEQ

log = logging.getLogger("uwgen.security")

STATE_VERSION = 2     # 2: records the sender id (a version 1 file is read, and rewritten as 2)
READ_VERSIONS = (1, 2)
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
        """Replace `path` by `data` atomically, never through a symlink (files.write_private)."""
        write_private(Path(path), data)


@dataclass
class State:
    key_id: str
    reserved: int = 0                      # the sender may use numbers below this
    floors: dict[int, int] = field(default_factory=dict)   # sender id -> replay floor
    sender: int | None = None              # the sender id the numbers were reserved for

    def to_bytes(self) -> bytes:
        return json.dumps({"version": STATE_VERSION, "key_id": self.key_id, "sender": self.sender,
                           "reserved": self.reserved,
                           "floors": {str(k): v for k, v in sorted(self.floors.items())}},
                          sort_keys=True).encode() + b"\n"


def _number(value, where: str, top: int) -> int:
    """`value` if it is an integer in 0..top (JSON floats, bools and strings are not)."""
    if type(value) is not int:
        raise ValueError(f"{where} is {value!r}, not an integer")
    if not 0 <= value <= top:
        raise ValueError(f"{where} = {value} is out of range 0..{top}")
    return value


def parse_state(data: bytes) -> State:
    """A State from the file's bytes; ValueError naming the field when anything is off."""
    try:
        obj = json.loads(data)
    except (UnicodeDecodeError, RecursionError) as exc:
        raise ValueError(f"not JSON text ({exc})") from None
    if not isinstance(obj, dict):
        raise ValueError("not a JSON object")
    if obj.get("version") not in READ_VERSIONS:
        raise ValueError(f"version {obj.get('version')!r} (this uwgen reads {READ_VERSIONS})")
    for name in ("key_id", "reserved", "floors"):
        if name not in obj:
            raise ValueError(f"no field {name!r}")
    key = obj["key_id"]
    if not isinstance(key, str) or len(key) != 16 or any(c not in "0123456789abcdef" for c in key):
        raise ValueError(f"key_id is {key!r}, not 16 hex digits")
    sender = obj.get("sender")
    if sender is not None or obj["version"] >= 2:
        sender = _number(sender, "sender", MAX_SENDER)
    floors = obj["floors"]
    if not isinstance(floors, dict):
        raise ValueError("floors is not an object")
    parsed = {}
    for k, v in floors.items():
        if not (k.isascii() and k.isdigit()):
            raise ValueError(f"floors: key {k!r} is not a sender id")
        parsed[_number(int(k), f"floors key {k}", MAX_SENDER)] = _number(v, f"floors.{k}", MAX_SEQ)
    return State(key, _number(obj["reserved"], "reserved", MAX_SEQ + 1), parsed, sender)


class StateFile:
    def __init__(self, path: Path, key_id: str, io: FileIO | None = None, sender: int | None = None):
        self.path = Path(path)
        self.key_id = key_id
        self.sender = sender
        self.io = io or FileIO()
        self._lock = SideLock(self.path.with_name(self.path.name + ".lock"),
                              f"the side whose security state is {self.path}")

    def lock(self) -> None:
        """Hold this file's lock until `unlock()`: SecurityError if another process holds it."""
        self._lock.acquire()

    def unlock(self) -> None:
        self._lock.release()

    def load(self) -> State:
        try:
            data = self.io.read(self.path)
        except OSError as exc:
            raise SecurityError(f"cannot read security state file {self.path}: {exc}") from None
        if data is None:
            log.warning("no security state file %s: this side's sequence numbers start at 0 "
                        "(if it ever sent with this key before, give the network a new key)", self.path)
            return State(self.key_id, sender=self.sender)
        try:
            state = parse_state(data)
        except ValueError as exc:
            raise SecurityError(
                f"security state file {self.path} is damaged ({exc}); starting over could repeat "
                "nonces: restore it, or generate a new network key (uwgen keygen) and delete it") from None
        if state.key_id != self.key_id:
            raise SecurityError(
                f"security state file {self.path} belongs to another key ({state.key_id}, this key "
                f"is {self.key_id}): give each key its own state file (the default path does)")
        if self.sender is not None:
            if state.sender is not None and state.sender != self.sender:
                raise SecurityError(
                    f"security state file {self.path} was written for sender id {state.sender}, "
                    f"but this side is sender {self.sender}: renumbering ids under one key could "
                    "repeat nonces; generate a new network key (uwgen keygen) for the new ids")
            state.sender = self.sender
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
        if self.next > MAX_SEQ:
            raise SecurityError(f"every sequence number of this key is used (2^43): generate a "
                                "new network key (uwgen keygen)")
        if self.next >= self.state.reserved:
            reserved = self.state.reserved
            self.state.reserved = min(self.next + self.block, MAX_SEQ + 1)
            try:
                self.store.save(self.state)
            except SecurityError:
                self.state.reserved = reserved
                raise
        seq = self.next
        self.next += 1
        return seq
