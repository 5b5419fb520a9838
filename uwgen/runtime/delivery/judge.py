"""How old a received command is, judged with its sender's measured clock offset, and the
log lines that say why one is refused (docs/wire-format.md section 15.5, docs/seams.md
section 8). `AgeJudge` holds the offsets (`clock_offset.ClockOffsets`), the rule
(`staleness.Staleness`) and the per-sender log lines; `Reliability` calls it with its lock held.
"""
from __future__ import annotations

import logging
from collections import OrderedDict
from typing import Any

from uwgen.runtime.clock import Clock
from uwgen.runtime.delivery.clock_offset import ClockOffsets
from uwgen.runtime.delivery.reliable import DELAY_UNIT, AckError, decode_reports, unwrap
from uwgen.runtime.delivery.staleness import (CLOCK_OFFSET, UNEXPLAINED, UNMEASURED, UNTIMED,
                                              Staleness, Verdict)
from uwgen.runtime.stats import Counters, log_count

BEGUN = 64            # commands taken whose beginning is kept for the bridge (`began`)

log = logging.getLogger("uwgen.link.reliability")


class AgeJudge:
    """One side's judgement of its peers' commands' ages."""

    def __init__(self, me: int, name: str, wall: Clock, counters: Counters,
                 max_ages: dict[int, float], peer_names: dict[int, str] | None = None,
                 measured_only: bool = False):
        self.sender, self.name, self.wall, self.counters = me, name, wall, counters
        self.max_ages = max_ages
        self.peer_names = dict(peer_names or {})
        self.staleness = Staleness(measured_only=measured_only)
        self.offsets = ClockOffsets()
        self.stale_by_id: dict[int, int] = {}
        self._offset_told: set[int] = set()
        self.first_offset_at: dict[int, float] = {}   # peer -> when its offset was first measured
        self.verdict: Verdict | None = None             # the last message's (`refuses`)
        # a command taken (its bytes as the bridge gets them) -> when it began (`taken`)
        self._began: OrderedDict[bytes, float] = OrderedDict()

    def who(self, peer: int) -> str:
        """`sender 1 (surface)`: the peer's sender id (W) and, when known, its side."""
        name = self.peer_names.get(peer)
        return f"sender {peer}" + (f" ({name})" if name else "")

    def sample(self, peer: int, envelope: Any, largest_sent: int | None, now: float) -> None:
        """The peer's report on our packets, with its packet's T: one NTP exchange."""
        if envelope.time is None or largest_sent is None:
            return
        try:
            reports = decode_reports(envelope.ack)
        except AckError:
            return
        for r in reports:
            if r.peer != self.sender:
                continue
            number = unwrap(r.largest, largest_sent)
            got = self.offsets.reported(peer, number, int(round(r.delay / DELAY_UNIT)),
                                        envelope.time, self.wall.now())
            if got is not None:
                self.counters.inc("offset_samples")
                self.first_offset_at.setdefault(peer, now)
                self._tell_offset(peer, got)

    def _tell_offset(self, peer: int, got) -> None:
        """One log line when a peer's offset is first measured beyond the tolerance (and
        again when it comes back within it)."""
        beyond = abs(got.offset) > self.staleness.tolerance
        back = abs(got.offset) + got.error <= self.staleness.tolerance   # no flapping at the edge
        if beyond and peer not in self._offset_told:
            self._offset_told.add(peer)
            log.error("[%s] %s's clock is %.1f s %s ours (+-%.2f s, measured from an "
                      "exchange), more than the %.0f s tolerance: its commands are refused "
                      "(counted clock_offset) until the clocks agree. Set both clocks from GPS "
                      "or NTP", self.name, self.who(peer), abs(got.offset),
                      "ahead of" if got.offset > 0 else "behind", got.error,
                      self.staleness.tolerance)
        elif back and peer in self._offset_told:
            self._offset_told.discard(peer)
            log.warning("[%s] %s's clock is now %.1f s from ours (+-%.2f s): within the "
                        "%.0f s tolerance, its commands are taken again", self.name, self.who(peer),
                        got.offset, got.error, self.staleness.tolerance)

    def _why(self, verdict, age: float, max_age: float) -> str:
        """Why `verdict` refused a message whose age item is `age` (the log line's reason)."""
        o, tolerance = verdict.offset, self.staleness.tolerance
        items = f"age item {age:.1f} s, max age {max_age:.1f} s"
        if verdict.refused == CLOCK_OFFSET:
            side = "ahead of" if o.offset > 0 else "behind"
            return (f"that sender's clock is {abs(o.offset):.1f} s {side} "
                    f"ours (+-{o.error:.2f} s), beyond the {tolerance:.0f} s tolerance. Set both clocks "
                    "from GPS or NTP")
        if verdict.refused == UNMEASURED:
            return ("that sender's clock offset is not measured yet (the exchange at start), so its "
                    f"age cannot be bounded ({items})")
        if verdict.refused == UNTIMED:
            return (f"its packet has no time (T), so how long it was held cannot be bounded ({items}); "
                    "a uwgen sender stamps T on every such packet")
        if verdict.refused == UNEXPLAINED:
            return (f"its packet's time says it took {verdict.transit:.1f} s on the way, outside "
                    f"[-{tolerance:.0f}, {tolerance + self.staleness.max_transit:.0f}] s, and that "
                    "sender's clock offset is not measured yet, so a delay cannot be told from an "
                    f"offset ({items})")
        how = (f"clock offset {o.offset:+.2f} +-{o.error:.2f} s measured" if o is not None else
               f"clock offset not measured yet (tolerance {tolerance:.0f} s)")
        how = f"transit {verdict.transit:.1f} s, {how}"
        return (f"it may be {verdict.age:.1f} s old (age item {age:.1f} s, {how}), "
                f"its max age is {max_age:.1f} s")

    def refuses(self, ident: int, peer: int, time24: int | None, age: float) -> bool:
        max_age = self.max_ages[ident]
        verdict = self.staleness.judge(time24, age, max_age, self.wall.now(), self.offsets.of(peer))
        self.verdict = verdict
        if verdict.refused is None:
            return False
        self.stale_by_id[ident] = self.stale_by_id.get(ident, 0) + 1
        n = self.counters.inc(verdict.refused)
        log_count(log, logging.WARNING, n, "[%s] refused a message of id %d from %s: %s (counted %s)",
                  self.name, ident, self.who(peer), self._why(verdict, age, max_age), verdict.refused)
        return True

    def taken(self, payload: bytes, now: float) -> None:
        """The command `payload` (its bytes as the bridge gets them), judged last
        (`refuses`), was taken at `now` (the link's clock): it began its likely age before
        (`Verdict.likely`). A command's copy carries its call's age (docs/wire-format.md
        section 15.6), so the serving side times its caller's deadline on the copy that
        came, not on its arrival. The last BEGUN are kept."""
        if self.verdict is None or self.verdict.refused is not None:
            return
        self._began[bytes(payload)] = now - self.verdict.likely
        self._began.move_to_end(bytes(payload))
        while len(self._began) > BEGUN:
            self._began.popitem(last=False)

    def began(self, payload: bytes) -> float | None:
        """When the command `payload` taken last began (`taken`), on the link's clock; None
        when it is not among the last BEGUN taken. Any thread (one dict lookup)."""
        return self._began.get(bytes(payload))
