"""What the per-packet seal says about a peer's clock (docs/security.md, "Clocks"): once per
sender, with the figure, when its packets are refused for their time T. Said only of packets
whose tag verified (`uwgen.security.packet_seal`), so a forgery cannot use a line up."""
from __future__ import annotations

from uwgen.runtime.clock import Clock
from uwgen.runtime.delivery.freshness import Freshness
from uwgen.runtime.wire import envelope as env
from uwgen.security.droplog import log


class ClockNotes:
    def __init__(self, name: str, peers: dict[int, str], freshness: Freshness, wall: Clock):
        self.name, self.peers, self.freshness, self.wall = name, peers, freshness, wall
        self._told_time: set[int] = set()       # peers whose refused time T was logged
        self._told_before: set[int] = set()     # peers whose far T before our start was logged

    def time_refused(self, e: env.Envelope) -> None:
        """A packet refused for its time T: say by how much, once per sender (a clock set
        wrong shows as every packet off by the same figure; a held packet as one late one)."""
        if e.sender in self._told_time:
            return
        self._told_time.add(e.sender)
        apparent = self.freshness.age(e.time, self.wall.now())
        log.error("[%s] sender %d (%s): a packet stamped %.1f s %s our clock was refused "
                  "(counted stale). If every packet of that sender is refused so, its clock and "
                  "ours disagree by about that much, beyond the %.0f s tolerance: set both from "
                  "GPS or NTP; if only some are, packets are being held back or replayed",
                  self.name, e.sender, self.peers.get(e.sender, "?"), abs(apparent),
                  "behind" if apparent > 0 else "ahead of", self.freshness.tolerance)

    def before_start(self, e: env.Envelope) -> None:
        """A packet refused `before_start` stamped further behind than the tolerance: its
        sender's clock may be that far behind; said once per sender, with the figure."""
        behind = self.freshness.age(e.time, self.wall.now())
        if e.sender in self._told_before or behind <= self.freshness.tolerance:
            return
        self._told_before.add(e.sender)
        log.warning("[%s] sender %d (%s): a packet of a new epoch stamped %.1f s behind our clock, "
                    "before this side started, was refused (counted before_start): a recording, "
                    "a packet held since before our start, or that sender's clock is about %.0f s "
                    "behind ours; if its clock, it is heard and its offset measured once its "
                    "stamps pass our start, and its commands refused (clock_offset) until both "
                    "clocks are set from GPS or NTP", self.name, e.sender,
                    self.peers.get(e.sender, "?"), behind, behind)
