"""The security control part C of an envelope (docs/wire-format.md section 12.3): pure.

C's L bytes are items of one byte each: bits 7-4 the code, bits 3-0 a sender id.

- code 1, *sync request*: "I hold no epoch of sender s: send your epoch (K) and time (T) in
  your next packets". Sent by a receiver that dropped a packet of s as `unsynced`, in a packet
  that is itself a sync packet (so s can take it even if it does not know the asker's epoch).

Codes 2 (turn grant, followed by one byte: the packets granted) and 3 (end of turn) are the
link's MAC's (uwgen.runtime.link.mac, docs/wire-format.md section 16): the seal skips them.
Other codes are reserved: a receiver counts them (`unknown_control`) and ignores them. C is
under the packet's tag, so only a key holder can ask, and only once per packet number.
"""
from __future__ import annotations

from dataclasses import dataclass

SYNC_REQUEST = 1
MAC_CODES = (2, 3)       # the link MAC's items (turn grant, end of turn)
TURN_GRANT = 2           # its item is two bytes: 2S, then the packets granted
MAX_SENDER = 15


@dataclass(frozen=True)
class Item:
    code: int
    sender: int

    def encode(self) -> int:
        if not 0 <= self.code <= 15 or not 0 <= self.sender <= MAX_SENDER:
            raise ValueError(f"control item code {self.code}, sender {self.sender}: each fits 4 bits")
        return (self.code << 4) | self.sender


def sync_request(sender: int) -> bytes:
    """The C bytes (without the length byte) asking `sender` for a sync."""
    return bytes((Item(SYNC_REQUEST, sender).encode(),))


def items(control: bytes) -> list[Item]:
    """The items of a C part's bytes (one byte each, a turn grant's count byte skipped:
    total, never fails)."""
    out, i = [], 0
    while i < len(control):
        out.append(Item(control[i] >> 4, control[i] & 0x0F))
        i += 2 if control[i] >> 4 == TURN_GRANT else 1
    return out


class SyncRequests:
    """Which peers this side should ask for a sync, and which requests it answers, each at most
    once per `gap` seconds per peer (so neither side can be made to add K and T to every packet:
    a request adds them to a few packets that were leaving anyway, never makes a packet)."""

    def __init__(self, gap: float):
        self.gap = gap
        self._asks: list[int] = []             # peers to ask, oldest first
        self._asked: dict[int, float] = {}     # peer -> when this side last asked it
        self._answered: dict[int, float] = {}  # peer -> when this side last answered it

    def want(self, peer: int, now: float) -> None:
        """A packet of `peer` was dropped `unsynced`: ask it, unless asked within the gap."""
        if peer not in self._asks and now - self._asked.get(peer, float("-inf")) >= self.gap:
            self._asks.append(peer)

    def next(self) -> int | None:
        """The peer the next packet asks (None: none)."""
        return self._asks[0] if self._asks else None

    def asked(self, peer: int, now: float) -> None:
        """A packet asking `peer` was built."""
        if peer in self._asks:
            self._asks.remove(peer)
        self._asked[peer] = now

    def heard(self, peer: int) -> None:
        """A packet of `peer` was admitted: no need to ask it any more."""
        if peer in self._asks:
            self._asks.remove(peer)

    def answer(self, peer: int, now: float) -> bool:
        """`peer` asked this side for a sync: whether to answer (not within the gap)."""
        if now - self._answered.get(peer, float("-inf")) < self.gap:
            return False
        self._answered[peer] = now
        return True
