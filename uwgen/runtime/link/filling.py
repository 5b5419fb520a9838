"""Filling the tail of a packet: which waiting message to take so the packet ends up fullest.

The link scheduler serves channels in claim order (uwgen.runtime.link.scheduler). Taken greedily,
claim order leaves a packet's last bytes empty whenever the next message in that order is a
little too long for them: with the demo's 6-14-byte messages a 64-byte packet then carries
59 bytes in two packets of three (measured, benchmarks/envelope_bench.py). Here the scheduler
asks instead: of the messages that could go next (one per ready channel, in claim order),
which is the first that still lets the room be filled as well as any choice could? Taking it
never makes the packet emptier than the best choice, and claims still move only for what is
served, so a channel passed over keeps its earlier claim and goes first in the next packet:
shares stay in proportion to weights.

Pure functions over sizes; a subset sum on a bit set (bit n set: n bytes reachable).
"""
from __future__ import annotations

from collections.abc import Sequence

from uwgen.runtime.wire.cuts import TAIL_HEAD
from uwgen.runtime.wire.envelope import (CUT_HEAD, EnvelopeError, Message, encode_messages,
                                         from_v1)

CUT_MIN = 3       # bytes of body a cut head carries at least: a cut costs 2 bytes of heads more
                  # than the whole message (63 and H' where H was, 64 and a length byte where
                  # its length byte was), so a smaller head hardly pays for the second packet
                  # the message then needs


def reachable(sizes: Sequence[int], budget: int) -> int:
    """Bit set of the totals (at most `budget`) that some subset of `sizes` adds up to."""
    mask = (1 << (budget + 1)) - 1
    r = 1
    for s in sizes:
        if 0 < s <= budget:
            r |= (r << s) & mask
    return r


def best_fill(sizes: Sequence[int], budget: int) -> int:
    """The largest total of a subset of `sizes` that is at most `budget`."""
    return reachable(sizes, budget).bit_length() - 1 if budget >= 0 else 0


def first_keeping_best(sizes: Sequence[int], budget: int) -> int | None:
    """Index of the first size (in the given order) that is part of some subset filling
    `budget` best; None when no size fits."""
    if sum(s for s in sizes if s <= budget) <= budget:        # everything fits: order decides
        return next((i for i, s in enumerate(sizes) if s <= budget), None)
    target = best_fill(sizes, budget)
    for i, s in enumerate(sizes):
        if s > budget:
            continue
        if reachable([*sizes[:i], *sizes[i + 1:]], budget - s) >> (target - s) & 1:
            return i
    return None


def cut_point(messages: Sequence[Message], message: Message, limit: int, room: int) -> int | None:
    """Where to cut `message` so that its head ends a packet already holding `messages`
    (`limit`: the bytes of messages the packet holds) and its tail starts a packet of `room`
    (its H and length byte counted, as a packet's room counts messages): the head's body
    length, or None when the head would carry less than CUT_MIN bytes, the tail nothing, or
    the tail would not fit (docs/wire-format.md section 14.2)."""
    base = len(encode_messages([*messages, Message(CUT_HEAD | message.kind, message.id, b"")]))
    first = limit - base
    if first < CUT_MIN or first >= len(message.body):
        return None
    if TAIL_HEAD + len(message.body) - first > room:
        return None
    return first


def added(messages: Sequence[Message], payload: bytes, base: int | None = None) -> int:
    """The bytes a wire format 1 `payload` adds to a packet holding `messages`, as encoded: its
    header, body and the length byte the message before it gains, or its body alone when it
    joins a run (what the scheduler compares with the room left). `base`: the length of
    `messages` encoded, when the caller knows it (a packet's fill measures every ready
    channel's next message against the same messages)."""
    try:
        m = from_v1(payload)
    except EnvelopeError:
        return len(payload) + 1
    if base is None:
        base = len(encode_messages(messages))
    return len(encode_messages([*messages, m])) - base
