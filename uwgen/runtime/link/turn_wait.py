"""The turns leader's wait for the turn it granted (docs/wire-format.md section 16, rule 3).

Sans-IO: `TurnMac` tells it the grant (`start`), every packet heard from a follower
(`heard`, with when it started arriving) and the time (`expired`); it says when the turn
is back. The bound is `TurnTiming.grant_deadline` (the manifest's physics): a lost grant or
a lost answer costs the wait for what could still come. A packet of the granted side moves
the bound to its remaining packets; its end gives the turn back at once and samples the
turn's round trip (`RoundTrip`, which only sizes a round). A follower's packet that starts
arriving after the bound its turn was taken back at is a late answer (`late_answers`): that
follower's later bounds grow by its lateness.
"""
from __future__ import annotations

from uwgen.manifest.mac import LISTEN
from uwgen.runtime.link.mac_base import INF
from uwgen.runtime.link.mac_items import TURN_END, MacItem
from uwgen.runtime.link.turn_timing import RoundTrip, TurnTiming, late_by


class TurnWait:
    """The leader's wait for one follower's turn at a time (module doc). `counts`: the MAC's
    counters, shared (`missed`, `ends_heard`, `late_answers`)."""

    def __init__(self, timing: TurnTiming, followers: list[int], counts: dict[str, int]):
        self.timing, self.counts = timing, counts
        # a turn's round trip besides its packets until measured: two trips, ticks and listens
        self.rtt = {sid: RoundTrip(2 * timing.one_way) for sid in followers}
        self._late = {sid: 0.0 for sid in followers}   # learned: answers later than the bound
        self.waiting: tuple[int, int, float, float] | None = None   # (sender, n, at, deadline)
        self._missed: tuple[int, float, float] | None = None   # (who, deadline, span), last missed
        self._unheard: dict[int, float] = {}   # follower -> when its turn was last taken back
        self._earliest = -INF             # no answer to the grant starts arriving before
        self._heard = 0                   # packets of the answer heard

    def start(self, sid: int, count: int, at: float, earliest: float, noticed_at: float | None) -> None:
        """Follower `sid` was given its `count`-packet turn at `at` (its grant's or its
        notice's write), its last notice written at `noticed_at`; no packet of its answer
        starts arriving before `earliest`."""
        deadline = self.timing.grant_deadline(at, count, noticed_at) + self._late[sid]
        self.waiting, self._earliest, self._heard = (sid, count, at, deadline), earliest, 0

    def deadline(self) -> float | None:
        return self.waiting[3] if self.waiting is not None else None

    def expired(self, now: float) -> bool:
        """Whether the bound passed with the turn unended (counted `missed`): the grant or
        the end was lost, and the turn is back."""
        if self.waiting is None or now < self.waiting[3]:
            return False
        self.counts["missed"] += 1
        who, _n, at, deadline = self.waiting
        self._missed = (who, deadline, deadline - at)
        self._unheard[who] = now
        self.waiting = None
        return True

    def heard(self, sender: int, items: list[MacItem], start: float, now: float) -> bool:
        """A packet of `sender` that started arriving at `start` (ended at `now`); True: it
        ended the turn awaited, which is back."""
        if self.waiting is None or sender != self.waiting[0] or start < self._earliest:
            self._heard_late(sender, start)     # not an answer to the grant
            return False
        self._heard += 1
        who, n, at, _deadline = self.waiting
        # It is answering: the rest of its turn has started arriving within its remaining
        # packets' intervals, whatever the first bound said: later (a late answer is never
        # talked over) or sooner (a lost end costs a packet's interval and DESERT's tick,
        # not a whole timeout).
        self.waiting = (who, n, at, self.timing.rest_deadline(start, max(0, n - self._heard)))
        if not any(i.code == TURN_END and i.sender == sender for i in items):
            return False
        self.counts["ends_heard"] += 1
        self.rtt[who].sample(max(0.0, now - at - (self._heard - 1) * self.timing.interval))
        self.waiting = None
        return True

    def _heard_late(self, sender: int, start: float) -> None:
        """A follower's packet that started arriving after the bound its turn was taken back
        at (`late_by`): later grants to it wait that much longer (`late_answers`)."""
        by = late_by(self._missed, sender, start)
        if by is not None:
            self.counts["late_answers"] += 1
            self._late[sender] = max(self._late[sender], by + LISTEN)

    def settled_by(self, sender: int) -> float | None:
        """When the turn awaited from `sender` was given (None: none awaited from it)."""
        waiting = self.waiting
        return waiting[2] if waiting is not None and sender == waiting[0] else None

    def unheard(self, sender: int) -> float | None:
        """When `sender`'s turn was last taken back on the bound (None: never)."""
        return self._unheard.get(sender)
