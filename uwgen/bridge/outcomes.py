"""What became of a service call that timed out (docs/wire-format.md section 5.1, "After a
timeout"; docs/demo.md "Service calls").

A ROS 2 caller whose bridged call got no response cannot tell whether the service ran. The
request itself is never executed after the call's `timeout` (the link refuses it older,
docs/wire-format.md section 15.5), so from then on nothing more will happen to it; what is
left to learn is whether it ran before. The calling side asks the serving side once the call
has timed out, with an **outcome query**: `[2, id, seq]` (the request's head, no fields: a
request always has at least one item, section 4). The serving side remembers the seqs it
handled (`Handled`) and answers
- with the response again when it ran and its response is kept: the calling side logs that
  the call ran (`ran_after_timeout`);
- `[3, id, seq]` (no fields) when it never handled that seq in this start: it did not run
  (`not_run`);
- nothing when it handled it without a response to give (the local server failed or timed
  out): the calling side counts `outcome_unknown` after asking `ASKS` times.
Not for rmw_desert-profile services (an rmw_desert server would take the query for a call).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

ASKS = 4                 # outcome queries per timed-out call, one retransmission timeout apart
HANDLED_MEMORY = 1024    # seqs per service the serving side remembers handling


def _uint(data: bytes, pos: int) -> tuple[int, int] | None:
    """A CBOR unsigned integer at `pos`: (value, next position), or None."""
    if pos >= len(data) or data[pos] >> 5 != 0:
        return None
    low = data[pos] & 0x1F
    if low < 24:
        return low, pos + 1
    size = {24: 1, 25: 2, 26: 4}.get(low)
    if size is None or pos + 1 + size > len(data):
        return None
    return int.from_bytes(data[pos + 1:pos + 1 + size], "big"), pos + 1 + size


def bare(payload: bytes) -> tuple[int, int, int] | None:
    """(kind, id, seq) when `payload` is those three items and nothing after: an outcome
    query (kind 2) or a 'did not run' answer (kind 3); None otherwise."""
    items, pos = [], 0
    for _ in range(3):
        got = _uint(payload, pos)
        if got is None:
            return None
        value, pos = got
        items.append(value)
    return (items[0], items[1], items[2]) if pos == len(payload) else None


def query(kind: int, ident: int, seq: int) -> bytes:
    """`[kind, id, seq]` as CBOR items."""
    from uwgen.runtime.wire.codec import pack_items
    return pack_items([kind, ident, seq])


@dataclass
class Asking:
    """A timed-out call the calling side asks about."""

    called: float          # when the call was made
    next_ask: float
    asks: int = 0


class Handled:
    """The seqs the serving side handed to its local server, per service, with when (bounded,
    oldest forgotten first)."""

    def __init__(self, memory: int = HANDLED_MEMORY):
        self.memory = memory
        self._seen: dict[int, OrderedDict[int, float]] = {}

    def add(self, ident: int, seq: int, now: float) -> None:
        seen = self._seen.setdefault(ident, OrderedDict())
        seen[seq] = now
        seen.move_to_end(seq)
        while len(seen) > self.memory:
            seen.popitem(last=False)

    def when(self, ident: int, seq: int) -> float | None:
        return self._seen.get(ident, {}).get(seq)

    def __contains__(self, key: tuple[int, int]) -> bool:
        return key[1] in self._seen.get(key[0], ())
