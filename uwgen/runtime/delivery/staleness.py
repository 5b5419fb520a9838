"""Is a received command too old? (docs/wire-format.md section 15.5, docs/seams.md section 8)

A message of an entry with a max age (a ttl, a service's timeout, a goal's accept_timeout)
arrives with the packet's T (when the sender built the packet, on its wall clock:
`uwgen.runtime.delivery.freshness`) and its age item (how long it waited before that, on the
sender's monotonic clock: `uwgen.runtime.wire.heads`). Its age on arrival is

    age + transit,   transit = receiver's wall clock - (T - offset)

where `offset` is the sender's clock minus ours. Three cases:

- the offset is measured (`clock_offset.ClockOffsets`, from an exchange): the message is
  refused `stale` when age + transit + error > max age, `error` being the measurement's bound:
  nothing older than its max age is taken, whatever the clocks and delays (a held packet's
  transit is counted in full). An offset beyond the tolerance refuses every message with a
  max age (`clock_offset`): the sides' clocks must be set (GPS, NTP) before commands run;
- the offset is not measured yet (the first packets after a start): the clocks are taken to
  agree within `tolerance`; a transit outside [-tolerance, tolerance + max_transit] cannot be
  told from an offset and the message is refused (`unexplained_delay`), never judged by its
  age item alone; otherwise it is refused `stale` when age + transit > max age + tolerance;
- the packet has no T: judged by its age item alone (counted `untimed` by the caller).

Pure: clocks and offsets are passed in.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.runtime.delivery.clock_offset import Offset
from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE, Freshness

MAX_TRANSIT = 10.0        # seconds: DESERT's queue, one acoustic packet, and margin

STALE, CLOCK_OFFSET, UNEXPLAINED = "stale", "clock_offset", "unexplained_delay"


@dataclass
class Verdict:
    refused: str | None           # None: taken; else STALE, CLOCK_OFFSET or UNEXPLAINED
    age: float                    # the message's age as judged (seconds), error included
    transit: float | None = None  # the packet's transit as judged (offset taken off when known)
    offset: Offset | None = None  # the sender's measured offset used

    @property
    def stale(self) -> bool:
        return self.refused is not None


@dataclass
class Staleness:
    tolerance: float = CLOCK_TOLERANCE
    max_transit: float = MAX_TRANSIT

    def judge(self, time24: int | None, age: float, max_age: float, wall: float,
              offset: Offset | None = None) -> Verdict:
        """`time24`: the packet's T (None: judged by `age` alone); `offset`: the sender's."""
        if time24 is None:
            return Verdict(STALE if age > max_age + self.tolerance else None, age)
        apparent = Freshness(self.tolerance).age(time24, wall)
        if offset is not None:
            transit = apparent + offset.offset
            if abs(offset.offset) > self.tolerance:
                return Verdict(CLOCK_OFFSET, age + max(transit, 0.0), transit, offset)
            total = age + max(transit, 0.0) + offset.error
            return Verdict(STALE if total > max_age else None, total, transit, offset)
        if not -self.tolerance <= apparent <= self.tolerance + self.max_transit:
            return Verdict(UNEXPLAINED, age + max(apparent, 0.0), apparent)
        total = age + max(apparent, 0.0)
        return Verdict(STALE if total > max_age + self.tolerance else None, total, apparent)
