"""Is a received command too old? (docs/wire-format.md section 15.5, docs/seams.md section 8)

A message of an entry with a max age (a ttl, a service's timeout, a goal's accept_timeout)
arrives with the packet's T (when the sender built the packet, on its wall clock:
`uwgen.runtime.delivery.freshness`) and its age item (how long it waited before that, on the
sender's monotonic clock, in quarter seconds rounded down: `uwgen.runtime.wire.heads`). Its
age on arrival is

    age + transit,   transit = receiver's wall clock - (T - offset)

where `offset` is the sender's clock minus ours. The judgement is conservative: a message is
taken only when the most it can be old is within its max age, so nothing is taken after its
deadline whatever the offset's error and however long a packet was held:

- the offset is measured (`clock_offset.ClockOffsets`, from an exchange, within +-`error`):
  refused `stale` when age + 1/4 s + max(0, transit + error) > max age (the age item's
  rounding and the offset's error both taken against the message). An offset beyond the
  tolerance refuses every message with a max age (`clock_offset`): the sides' clocks must be
  set (GPS, NTP) before commands run;
- the offset is not measured yet (the first packets after a start): the clocks are taken to
  agree within `tolerance`, which is then the offset's error: a transit outside
  [-tolerance, tolerance + max_transit] cannot be told from an offset and the message is
  refused (`unexplained_delay`), never judged by its age item alone; otherwise it is refused
  `stale` when age + 1/4 s + max(0, transit + tolerance) > max age;
  On a link whose sides measure each other at start (`measured_only`, the bridges' probes),
  a message with a max age is refused `unmeasured` until its sender's offset is measured:
  the clocks' agreement is then not assumed, since nothing enforces it;
- the packet has no T: refused (`untimed`). A sender stamps T on every packet carrying a
  message with a max age (wire-format.md section 15.5), so such a packet was not built by
  one, and an age item alone bounds nothing: a packet held for an hour says the same age.

Pure: clocks and offsets are passed in.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.runtime.delivery.clock_offset import Offset
from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE, Freshness
from uwgen.runtime.wire.heads import AGE_UNIT

MAX_TRANSIT = 10.0        # seconds: DESERT's queue, one acoustic packet, and margin

STALE, CLOCK_OFFSET, UNEXPLAINED = "stale", "clock_offset", "unexplained_delay"
UNMEASURED = "unmeasured"   # no offset yet, on a link whose sides measure each other at start
UNTIMED = "untimed"         # no T on the packet: nothing bounds the hold


@dataclass
class Verdict:
    refused: str | None           # None: taken; else the reason (STALE, CLOCK_OFFSET, ...)
    age: float                    # the most the message can be old (seconds)
    transit: float | None = None  # the packet's transit as judged (offset taken off when known)
    offset: Offset | None = None  # the sender's measured offset used
    item: float = 0.0             # the age item read (seconds)

    @property
    def stale(self) -> bool:
        return self.refused is not None

    @property
    def likely(self) -> float:
        """The message's age as best known, not the bound `age`: its age item, half the
        item's rounding and the transit (the offset taken off when measured, its error not
        counted). What the receiver times a call's deadline on (`AgeJudge.taken`)."""
        return self.item + AGE_UNIT / 2 + max(self.transit or 0.0, 0.0)


@dataclass
class Staleness:
    tolerance: float = CLOCK_TOLERANCE
    max_transit: float = MAX_TRANSIT
    # the sides exchange times at start (the bridges' probes): until a peer's offset is
    # measured, nothing bounds it (a clock 60 s ahead makes a 56 s old recording look 4 s
    # early), so a message with a max age is refused (`unmeasured`) rather than trusted
    measured_only: bool = False

    def judge(self, time24: int | None, age: float, max_age: float, wall: float,
              offset: Offset | None = None) -> Verdict:
        """`time24`: the packet's T (None: refused, module doc); `offset`: the sender's."""
        if time24 is None:
            return Verdict(UNTIMED, float("inf"))
        apparent = Freshness(self.tolerance).age(time24, wall)
        if offset is not None:
            transit = apparent + offset.offset
            most = age + AGE_UNIT + max(transit + offset.error, 0.0)
            if abs(offset.offset) > self.tolerance:
                return Verdict(CLOCK_OFFSET, most, transit, offset, item=age)
            return Verdict(STALE if most > max_age else None, most, transit, offset, item=age)
        most = age + AGE_UNIT + max(apparent + self.tolerance, 0.0)
        if self.measured_only:
            return Verdict(UNMEASURED, most, apparent, item=age)
        if not -self.tolerance <= apparent <= self.tolerance + self.max_transit:
            return Verdict(UNEXPLAINED, most, apparent, item=age)
        return Verdict(STALE if most > max_age else None, most, apparent, item=age)
