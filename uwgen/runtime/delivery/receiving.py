"""The receiving side of the reliability engine (docs/wire-format.md sections 15.2 and 15.4):
each peer's packet numbers (`received`), the report that acknowledges them (`ack_for`: the
largest number and a bitmap of the ones before, as SACK blocks and LTP report segments do),
when an ack must go alone (`ack_only_due`), and delivery once of a reliable message
(`deliver_once`). `ReliableLink` (reliable.py) is this and its sending side. Pure."""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

from uwgen.runtime.delivery.reports import MAX_BITMAP, NUMBER_MOD, Report, encode_reports, unwrap

RECEIVED_WINDOW = 8 * MAX_BITMAP + 1   # numbers below the largest a receiver remembers
DELIVERED_MEMORY = 128           # message numbers per entry remembered for delivery once


@dataclass
class PeerReceipts:
    """A receiver's record of one peer's (sender id, epoch) packet numbers."""

    largest: int | None = None
    got: set[int] = field(default_factory=set)      # numbers in the window below largest
    largest_at: float = 0.0
    unacked: int = 0                                # eliciting packets since our last ack
    eliciting_since: float | None = None
    gap: bool = False                               # a number was skipped since our last ack:
                                                    # the packet lost may have carried a reliable
                                                    # message, so the next packet leaving reports
    duplicates: int = 0
    too_old: int = 0                                # numbers below the window: taken, not recorded
    gaps: int = 0                                   # numbers that left the window unreceived


class Receiving:
    """Every peer's (sender id, epoch) packets as received, and the reliable messages delivered."""

    def __init__(self, bitmap_bytes: int = 2):
        self.bitmap_bytes = min(MAX_BITMAP, bitmap_bytes)
        self.receipts: dict[tuple[int, bytes], PeerReceipts] = {}
        self._delivered: dict[tuple[int, bytes, int], OrderedDict[int, None]] = {}
        self.duplicates: dict[int, int] = {}          # key -> reliable copies delivered twice
        self.ack_delay = 0.0                          # how long an ack may wait (the engine's)

    def received(self, peer: int, epoch: bytes, number: int, now: float,
                 eliciting: bool) -> bool:
        """Packet `number` (mod 4096) from (peer, epoch) arrived. False: a repeat of a packet
        received (DESERT delivered it twice; counted `duplicates`): nothing of it is taken, its
        messages must not be delivered. `eliciting`: it carries a reliable message, so the peer
        waits for an ack of it. A number further below the largest than the window remembers
        cannot be told from a new one after a long loss (numbers are 12 bits): it is counted
        `too_old` and taken, never dropped on a guess."""
        r = self.receipts.get((peer, epoch))
        if r is None:
            # A new epoch is a restarted peer: everything known about the old one goes.
            for old in [k for k in self.receipts if k[0] == peer]:
                del self.receipts[old]
            r = self.receipts[(peer, epoch)] = PeerReceipts()
        n = number if r.largest is None else unwrap(number, r.largest)
        if r.largest is not None and (n == r.largest or n in r.got):
            r.duplicates += 1
            return False
        if r.largest is not None and n < r.largest - RECEIVED_WINDOW:
            r.too_old += 1                      # too old to tell: not remembered, not acked
            return True
        if r.largest is None or n > r.largest:
            if r.largest is not None:
                r.got.add(r.largest)
                low = n - RECEIVED_WINDOW
                r.got = {x for x in r.got if x >= low}
                r.gaps += n - r.largest - 1          # numbers skipped (missing so far)
                r.gap = r.gap or n > r.largest + 1
            r.largest, r.largest_at = n, now
        else:
            r.got.add(n)
            r.gaps -= 1                          # a number counted missing came after all
        if eliciting:
            r.unacked += 1
            if r.eliciting_since is None:
                r.eliciting_since = now
        return True

    def ack_for(self, peer: int, now: float, *, any_news: bool = True,
                nbytes: int | None = None) -> bytes | None:
        """The A part about `peer`'s packets for a packet leaving now (None: nothing to say).
        Sent when packets of the peer arrived since our last ack (`unacked`); with
        `any_news` False only when the peer waits for one (eliciting packets)."""
        r = self._current(peer)
        if r is None or r.largest is None or (r.unacked == 0 and r.eliciting_since is None
                                              and not any_news):
            return None
        nbytes = self.bitmap_bytes if nbytes is None else max(0, min(MAX_BITMAP, nbytes))
        bitmap = 0
        for i in range(8 * nbytes):
            bitmap = bitmap << 1 | ((r.largest - 1 - i) in r.got)
        r.unacked, r.eliciting_since, r.gap = 0, None, False
        return encode_reports([Report(peer, r.largest % NUMBER_MOD, bitmap, nbytes,
                                      now - r.largest_at)])

    def ack_only_due(self, peer: int, now: float) -> bool:
        """True when the peer waits for an ack and none has ridden on a packet for
        `ack_delay`: the link should send a packet with only the A part."""
        r = self._current(peer)
        return r is not None and r.eliciting_since is not None and now - r.eliciting_since >= self.ack_delay

    def rename_epoch(self, peer: int, old: bytes, new: bytes) -> None:
        """What was kept of `peer` under a stand-in epoch (`old`: not known yet) is its epoch
        `new`, learnt from K: the same start, not a restart."""
        r = self.receipts.pop((peer, old), None)
        if r is not None:
            self.receipts[(peer, new)] = r
        for (p, e, key) in [k for k in self._delivered if k[0] == peer and k[1] == old]:
            self._delivered[(p, new, key)] = self._delivered.pop((p, e, key))

    def _current(self, peer: int) -> PeerReceipts | None:
        for (p, _epoch), r in self.receipts.items():
            if p == peer:
                return r
        return None

    def deliver_once(self, sender: int, epoch: bytes, key: int, msg_id: int) -> bool:
        """True the first time a reliable message (its head's number N) arrives; False for a
        copy (counted in `duplicates[key]`)."""
        seen = self._delivered.setdefault((sender, epoch, key), OrderedDict())
        if msg_id in seen:
            self.duplicates[key] = self.duplicates.get(key, 0) + 1
            return False
        seen[msg_id] = None
        while len(seen) > DELIVERED_MEMORY:
            seen.popitem(last=False)
        return True
