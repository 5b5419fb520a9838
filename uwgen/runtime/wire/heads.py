"""The reliability head of a message (docs/wire-format.md sections 15.4 and 15.5).

In wire format 2 a message's body may start with a head that the link adds as the message
leaves its queue and takes off before the message is delivered, so generated codecs never
see it. Which entries carry which item is fixed by the manifest (both sides build from it,
and the schema fingerprint makes sure they agree):

- N, one byte: the message number of a *reliable* entry (`reliability: reliable`), counted
  per entry by the sender mod 256; the receiver delivers each (sender, epoch, entry, N) once;
- age, a CBOR unsigned integer: for an entry with a max age (a ttl, or a command's
  timeout), how long the message waited between its publication and the packet that
  carries it, in quarter seconds, rounded down (1 byte below 6 s, 2 below 64 s, 3 below
  4.5 h; larger ages are sent as 65535). The packet's T is when it was built, so the
  message was published at T - age.

N comes first when an entry has both. This module is pure: bytes and numbers in and out.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from uwgen.runtime.wire.envelope import EnvelopeError, Message, from_v1, to_v1

AGE_UNIT = 0.25               # seconds per unit of the age item
MAX_AGE_UNITS = 0xFFFF        # a 3-byte CBOR item at most
MAX_HEAD = 1 + 3              # N and the longest age item


class HeadError(ValueError):
    """A received message whose head is cut short or not what its entry carries."""


def encode_age(seconds: float) -> bytes:
    units = min(MAX_AGE_UNITS, max(0, int(seconds / AGE_UNIT)))
    if units < 24:
        return bytes((units,))
    if units < 256:
        return bytes((0x18, units))
    return bytes((0x19,)) + units.to_bytes(2, "big")


def decode_age(body: bytes, pos: int) -> tuple[float, int]:
    """(age in seconds, position after the item); HeadError when it is no such item."""
    if pos >= len(body):
        raise HeadError("the message ends before its age item")
    b = body[pos]
    if b < 24:
        return b * AGE_UNIT, pos + 1
    size = {0x18: 1, 0x19: 2}.get(b)
    if size is None or pos + 1 + size > len(body):
        raise HeadError(f"the age item starts with {b:02X}: not a CBOR unsigned of at most "
                        f"2 bytes, or cut short")
    units = int.from_bytes(body[pos + 1:pos + 1 + size], "big")
    if (size == 1 and units < 24) or (size == 2 and units < 256):
        raise HeadError(f"the age item {units} is not in its shortest form")
    return units * AGE_UNIT, pos + 1 + size


@dataclass
class Received:
    """A received message with its head read: the payload the codecs read, N and age."""

    payload: bytes
    number: int | None = None
    age: float | None = None


@dataclass
class Heads:
    """Which wire ids carry N (`numbered`) and an age (`aged`); the sender's counters."""

    numbered: frozenset[int] = frozenset()
    aged: frozenset[int] = frozenset()
    _next: dict[int, int] = field(default_factory=dict)

    def room(self, ident: int) -> int:
        """The most bytes the head of a message of `ident` takes."""
        return (ident in self.numbered) + (3 if ident in self.aged else 0)

    def add(self, payload: bytes, age: float) -> tuple[bytes, int | None]:
        """`payload` (wire format 1) with the head of its entry; also its N (None: none)."""
        m = from_v1(payload)
        head, number = b"", None
        if m.id in self.numbered:
            number = self._next.get(m.id, 0)
            self._next[m.id] = (number + 1) % 256
            head = bytes((number,))
        if m.id in self.aged:
            head += encode_age(age)
        if not head:
            return payload, None
        return to_v1(Message(m.kind, m.id, head + m.body)), number

    def take(self, payload: bytes) -> Received:
        """The head of a received payload read and taken off (HeadError when malformed)."""
        try:
            m = from_v1(payload)
        except EnvelopeError:
            return Received(payload)                 # not a message of ours: left to dispatch
        if m.id not in self.numbered and m.id not in self.aged:
            return Received(payload)
        pos, number, age = 0, None, None
        if m.id in self.numbered:
            if not m.body:
                raise HeadError(f"message of id {m.id} has no message number")
            number, pos = m.body[0], 1
        if m.id in self.aged:
            age, pos = decode_age(m.body, pos)
        return Received(to_v1(Message(m.kind, m.id, m.body[pos:])), number, age)
