"""Time on the link: the 3-byte time T of an envelope (and of a sync word), and whether it is fresh.

Shared by the commands' `stale` check (wire-format.md section 15.5) and security's freshness
(section 12): one mechanism for time (docs/seams.md section 4), so it lives in the runtime,
below both.

A sender stamps each sync word with its wall clock when it seals the frame, as the envelope's
T part (docs/seams.md section 1) will: a 24-bit count of 1/32 s since the UNIX epoch, mod 2^24
(it wraps every 6.07 days). The receiver reads it as the time closest to its own wall clock
with those 24 bits, so it needs no date, and judges it with `Freshness`:

- older than the entry's max age (plus the clock tolerance): `stale` (a recorded or held-back
  frame);
- ahead of the receiver's clock by more than the tolerance: also refused, as `stale` (a clock
  that is off, or a forged time; the receiver cannot tell which, so it takes neither);
- for a sender's epoch the receiver does not know yet: sealed before the receiver started
  (`before`, no tolerance: a receiver that lost its memory takes nothing recorded earlier).

The sides' wall clocks must agree within `tolerance` (5 s by default): on a vehicle, set them
from GPS or NTP at the surface. Everything here is pure: clocks are passed in.
"""
from __future__ import annotations

from dataclasses import dataclass

TICKS_PER_SECOND = 32
TIME_BITS = 24
TIME_SPAN = 1 << TIME_BITS
MAX_AGE = 120.0           # seconds: an entry without a ttl
CLOCK_TOLERANCE = 5.0     # seconds the sides' wall clocks may disagree


def stamp(wall: float) -> int:
    """The 24-bit time of `wall` (seconds since the UNIX epoch)."""
    return int(wall * TICKS_PER_SECOND) % TIME_SPAN


def sent_at(time24: int, wall: float) -> float:
    """The wall time, closest to `wall`, whose stamp is `time24`."""
    base = int(wall * TICKS_PER_SECOND)
    delta = (time24 - base) % TIME_SPAN
    if delta >= TIME_SPAN // 2:
        delta -= TIME_SPAN
    return (base + delta) / TICKS_PER_SECOND


@dataclass(frozen=True)
class Freshness:
    tolerance: float = CLOCK_TOLERANCE

    def age(self, time24: int, wall: float) -> float:
        """Seconds since a frame stamped `time24` was sealed (negative: from the future)."""
        return wall - sent_at(time24, wall)

    def before(self, time24: int, wall: float, start: float) -> bool:
        """Whether a frame stamped `time24` was sealed before `start` (both clocks taken as
        they are: a sender's clock ahead by d lets in frames sealed up to d before `start`,
        one behind by d makes its frames wait d longer)."""
        return sent_at(time24, wall) + 1 / TICKS_PER_SECOND <= start   # a stamp is rounded down

    def fresh(self, time24: int, wall: float, max_age: float) -> bool:
        age = self.age(time24, wall)
        return -self.tolerance <= age <= max_age + self.tolerance
