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

N comes first when an entry has both.

One age item a packet is not sent (wire-format.md section 14.3): on a packet with T but no K, no
A part and no fragment, carrying exactly one whole message of an entry with a max age, T is
that message's publication time (the build time less its age) and its age item is left out:
`without_age` makes that packet from the usual one as it leaves, `with_age` gives a received
one its age item back (0: T is the publication time), so everything after reads the same head
and judges the same age. This module is pure: bytes and numbers in and out.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from uwgen.runtime.wire.envelope import FRAGMENT, TIME_LEN, Envelope, EnvelopeError, Message, from_v1, to_v1

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
    # the aged ids whose age may ride in T (section 14.3): those whose max age is at most the
    # seal's default, which a sealed packet's T is checked against (None: every aged id)
    lone: frozenset[int] | None = None
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

    def aged_again(self, payload: bytes, age: float) -> bytes:
        """`payload` as `add` stamped it, with its age item rewritten to `age` (a copy sent
        again is as old as the message, not as it was when first sent); N is kept."""
        m = from_v1(payload)
        if m.id not in self.aged:
            return payload
        pos = 1 if m.id in self.numbered else 0
        _, end = decode_age(m.body, pos)
        return to_v1(Message(m.kind, m.id, m.body[:pos] + encode_age(age) + m.body[end:]))

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

    # -- one age item a packet left out (section 14.3) ----------------------------------------

    def lone_aged(self, envelope: Envelope) -> int | None:
        """The index of the packet's one message when its T stands for that message's
        publication: T, no K, no A part, and one message alone, whole, of an id in `aged` and
        `lone`; else None (T is the build time and every message with a max age has its age
        item)."""
        # One message and nothing else: the rule reads only what both sides see in the
        # packet, never which ids the reader knows to be aged (a fleet vehicle knows only its
        # own entries, and two aged messages of two vehicles would look lone to each).
        if (envelope.time is None or envelope.sync is not None or envelope.ack is not None
                or len(envelope.messages) != 1):
            return None
        m = envelope.messages[0]
        if m.kind == FRAGMENT or m.id not in self.aged or (self.lone is not None and m.id not in self.lone):
            return None
        return 0

    def without_age(self, envelope: Envelope, ticks_per_second: int) -> Envelope:
        """The envelope as it is sent: for a lone aged message (`lone_aged`), its age item
        left out and T moved back by that age (T's ticks of 1/`ticks_per_second` s)."""
        k = self.lone_aged(envelope)
        if k is None:
            return envelope
        m = envelope.messages[k]
        pos = 1 if m.id in self.numbered else 0
        try:
            age, end = decode_age(m.body, pos)
        except HeadError:
            return envelope                  # not a head of ours: sent as it is
        time = (envelope.time - round(age * ticks_per_second)) % (1 << 8 * TIME_LEN)
        messages = list(envelope.messages)
        messages[k] = Message(m.kind, m.id, m.body[:pos] + m.body[end:])
        return replace(envelope, messages=tuple(messages), time=time)

    def with_age(self, envelope: Envelope) -> Envelope:
        """A received envelope with its lone aged message's age item back: 0, since T is
        that message's publication time."""
        k = self.lone_aged(envelope)
        if k is None:
            return envelope
        m = envelope.messages[k]
        pos = min(len(m.body), 1 if m.id in self.numbered else 0)
        messages = list(envelope.messages)
        messages[k] = Message(m.kind, m.id, m.body[:pos] + encode_age(0.0) + m.body[pos:])
        return replace(envelope, messages=tuple(messages))
