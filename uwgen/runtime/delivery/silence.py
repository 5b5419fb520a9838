"""A peer's packet with no report where it would have reported (docs/wire-format.md section
15.2, "Silence"). Pure: `uwgen.runtime.delivery.reliability.Reliability` tells it what left
and what arrived without an A part.

A packet that carries a reliable message or a command elicits a report: the receiver names
it on the next packet it builds (acks.AckPolicy, `waited`; every packet leaves room for
one). Under turns the MAC knows when everything this side wrote until a moment had reached a
peer or been lost before a packet of that peer was built (`settled_by`). So a packet of the
peer that arrives with no A part at all, built after an eliciting packet of ours had
settled, says that packet never reached the peer, provided every packet of the peer numbered
after the last one we had heard when ours left has arrived: none lost could have carried
the report. Ours is then overtaken, as a report not naming it would say
(`ReliableLink.overtaken`): its commands are told lost and its reliable messages go again,
a round before the peer's next report would tell (when the peer heard none of our later
packets either, a report waits for news: section 15.2). The ledger still waits for a report
to settle it; should the packet have arrived after all, its copies are spurious and
delivered once.
"""
from __future__ import annotations

from collections import OrderedDict

from uwgen.runtime.delivery.reliable import REPORT_KEY, ReliableLink, Sent
from uwgen.runtime.delivery.reports import unwrap

KEPT = 64     # our packets whose marks are kept (older ones have settled long before)


class Silence:
    """What a peer's packets with no report say of ours (module doc)."""

    def __init__(self, engine: ReliableLink):
        self.engine = engine
        # our packet number -> (peer, epoch) -> the peer's largest number heard when it left
        self._marks: OrderedDict[int, dict[tuple[int, bytes], int]] = OrderedDict()
        self.inferred = 0              # our packets taken as lost from a peer's silence

    def sent(self, number: int) -> None:
        """Our packet `number` left: what we had heard of each peer then."""
        self._marks[number] = {k: r.largest for k, r in self.engine.receipts.items()
                               if r.largest is not None}
        while len(self._marks) > KEPT:
            self._marks.popitem(last=False)

    def heard(self, peer: int, epoch: bytes, number: int, settled_by: float | None,
              now: float) -> None:
        """Packet `number` of (`peer`, `epoch`), with no A part, was taken at `now`; everything
        we wrote until `settled_by` had reached the peer or been lost before it was built
        (None: the MAC cannot say, and nothing follows)."""
        r = self.engine.receipts.get((peer, epoch))
        if settled_by is None or r is None or r.largest is None \
                or unwrap(number, r.largest) != r.largest:
            return                            # a late packet of the peer's says less
        for packet in list(self.engine.outstanding.values()):
            mark = self._marks.get(packet.number, {}).get((peer, epoch))
            if mark is None or packet.at > settled_by or packet.told or not packet.awaits(peer):
                continue
            if mark < r.largest and self._elicits(packet.messages) \
                    and all(n in r.got for n in range(mark + 1, r.largest)):
                del self._marks[packet.number]      # taken once
                self.inferred += 1
                self.engine.overtaken(packet, now)

    def _elicits(self, messages: list[Sent]) -> bool:
        """Whether the peer reports on a packet carrying `messages` on its next packet: a
        whole reliable message or command among them (a cut one's head elicits nothing)."""
        return any(m.key != REPORT_KEY and m.tail is None
                   and (m.deadline is not None or m.key in self.engine.told.watched)
                   for m in messages)
