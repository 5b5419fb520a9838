"""Is a received command too old? (docs/wire-format.md section 15.5, docs/seams.md section 4)

A message of an entry with a max age (a ttl, a command's timeout) arrives with the packet's T
(when the sender built the packet, on its wall clock: `uwgen.runtime.delivery.freshness`) and its age
item (how long it waited before that, on the sender's monotonic clock: `uwgen.runtime.wire.heads`).
Its age on arrival is

    age + transit,   transit = receiver's wall clock - T

and it is refused (`stale`) when that exceeds the entry's max age plus the clock tolerance
(the sides' clocks agree within `tolerance`; the same rule as security's `Freshness.fresh`).

The transit of one acoustic packet is seconds at most. A transit outside
[-tolerance, tolerance + max_transit] says the clocks disagree by more than the tolerance:
the receiver then cannot judge the transit, says so (one log line per sender, counted
`clock_offset` per message) and judges the message by its age item alone (clock-free),
instead of silently refusing everything that sender sends. Pure: clocks are passed in.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE, Freshness

MAX_TRANSIT = 10.0        # seconds: DESERT's queue, one acoustic packet, and margin


@dataclass
class Verdict:
    stale: bool
    age: float                    # what the judgement used (seconds)
    offset: float | None = None   # the apparent transit when it says the clocks disagree


@dataclass
class Staleness:
    tolerance: float = CLOCK_TOLERANCE
    max_transit: float = MAX_TRANSIT
    offsets: dict[int, float] = field(default_factory=dict)   # sender -> last apparent offset

    def judge(self, sender: int, time24: int | None, age: float, max_age: float,
              wall: float) -> Verdict:
        """`time24`: the packet's T (None: the packet had none: judged by `age` alone)."""
        if time24 is None:
            return Verdict(age > max_age + self.tolerance, age)
        transit = Freshness(self.tolerance).age(time24, wall)
        if -self.tolerance <= transit <= self.tolerance + self.max_transit:
            self.offsets.pop(sender, None)
            total = age + max(transit, 0.0)
            return Verdict(total > max_age + self.tolerance, total)
        self.offsets[sender] = transit
        return Verdict(age > max_age + self.tolerance, age, transit)
