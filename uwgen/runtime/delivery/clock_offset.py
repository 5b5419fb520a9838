"""Each peer's clock offset, measured from an exchange (docs/seams.md section 8,
docs/wire-format.md section 15.5).

NTP's four timestamps, from what the link carries anyway:

- t1: this side's wall clock when it built packet n (kept here by packet number, never sent);
- t2 = t3 - hold: when the peer received n, on the peer's clock (the report's ack delay, R1 of
  wire-format.md section 15.2, is how long the peer held n before its report left);
- t3: the T of the packet carrying that report (the peer's clock when it built it);
- t4: this side's wall clock when that packet arrived.

    offset = ((t2 - t1) + (t3 - t4)) / 2        the peer's clock minus ours
    delay  = (t4 - t1) - hold                   both transits, the hold taken off
    error  = delay / 2 + quantisation           the offset is within +-error of the truth

whatever the two transits are (each is >= 0): the only assumption is that a packet does not
arrive before it left. The hold is sent in whole quarter seconds, rounded down (taken at the
middle of its quarter, +-1/8 s), T in 1/32 s rounded down (+-1/32 s at each end). As NTP's
clock filter does, the sample of the least delay among the peer's last `KEEP` wins: a packet
held back by the channel, a queue or an attacker only makes its own sample worse, never the
estimate.

A saturated hold (15 quarters: 3.75 s or more) still bounds the exchange from one side: the
peer received n at least 3.75 s before t3, so t2 <= t3 - 3.75, and the offset lies within
[t3 - t4, t3 - 3.75 - t1] whatever the transits. The sample is that range: the formulas above
with hold = 3.75 s, its delay counting the hold beyond 3.75 s as transit, so any exact sample
of less delay wins the filter. It is what measures a peer that always holds our packets that
long (a TDMA slot far from ours: under a frame of 6 s the last of eight vehicles reports the
surface's packets about 4 s after hearing them). A saturated report whose range is wider than
`SATURATED_REACH` (a report naming an old packet again, not an exchange) or empty (the round
trip was shorter than the hold it claims) gives no sample.

A single late packet never moves the estimate: every sample needs a packet of this side that
the peer received and reported, and a held packet makes a sample with a large delay that loses
the filter. Pure: clocks are passed in.
"""
from __future__ import annotations

from collections import OrderedDict, deque
from dataclasses import dataclass

from uwgen.runtime.delivery.freshness import TICKS_PER_SECOND, sent_at

HOLD_UNIT = 0.25            # seconds per unit of a report's ack delay (wire-format 15.2, R1)
HOLD_SATURATED = 15         # units: "15 or more": held at least 3.75 s (module doc)
SATURATED_REACH = HOLD_SATURATED * HOLD_UNIT   # the widest delay a saturated sample may have
KEEP = 8                    # samples per peer the filter chooses from (NTP's clock filter)
REMEMBER = 512              # our packets whose build time is kept (a report names recent ones)
QUANTUM = HOLD_UNIT / 2 + 2 / TICKS_PER_SECOND   # the rounding of the hold and of two Ts


@dataclass(frozen=True)
class Offset:
    """A peer's clock minus ours (`offset`, seconds), within +-`error`; `delay` is the round
    trip of the exchange it came from, `samples` how many exchanges were seen."""

    offset: float
    error: float
    delay: float
    samples: int

    def as_dict(self) -> dict:
        return {"offset": round(self.offset, 3), "error": round(self.error, 3),
                "delay": round(self.delay, 3), "samples": self.samples}


def sample(t1: float, hold: float, t3: float, t4: float) -> tuple[float, float, float]:
    """(offset, delay, error) of one exchange; `hold` is the peer's reported hold in seconds
    (the middle of its quarter second)."""
    t2 = t3 - hold
    offset = ((t2 - t1) + (t3 - t4)) / 2
    delay = max(0.0, (t4 - t1) - hold)
    return offset, delay, delay / 2 + QUANTUM


class ClockOffsets:
    """The offsets of every peer of one side."""

    def __init__(self, keep: int = KEEP, remember: int = REMEMBER):
        self.keep, self.remember = keep, remember
        self._built: OrderedDict[int, float] = OrderedDict()     # our packet number -> t1
        self._samples: dict[int, deque[tuple[float, float, float]]] = {}
        self._counts: dict[int, int] = {}

    def built(self, number: int, wall: float) -> None:
        """This side built packet `number` (its full number) at wall time `wall`."""
        self._built[number] = wall
        while len(self._built) > self.remember:
            self._built.popitem(last=False)

    def reported(self, peer: int, number: int, hold_units: int, time24: int | None,
                 wall: float) -> Offset | None:
        """The peer reported our packet `number` (full), held `hold_units` quarter seconds, in
        a packet stamped `time24` that arrived at `wall`. Returns the new estimate, or None
        when the report gives no sample (no T, a packet we no longer know, a saturated hold
        whose range is empty or wider than `SATURATED_REACH`)."""
        t1 = self._built.get(number)
        if time24 is None or t1 is None or hold_units < 0:
            return None
        if wall < t1:
            return None                      # our own clock stepped back: not an exchange
        saturated = hold_units >= HOLD_SATURATED
        hold = HOLD_SATURATED * HOLD_UNIT if saturated else (hold_units + 0.5) * HOLD_UNIT
        if saturated and not 0 <= wall - t1 - hold <= SATURATED_REACH:
            return None                      # an empty range, or one too wide to tell
        offset, delay, error = sample(t1, hold, sent_at(time24, wall), wall)
        kept = self._samples.setdefault(peer, deque(maxlen=self.keep))
        now = self.of(peer)
        if now is not None and abs(offset - now.offset) > error + now.error:
            kept.clear()        # the ranges do not meet: a clock was stepped; measure anew
        kept.append((delay, offset, error))
        self._counts[peer] = self._counts.get(peer, 0) + 1
        return self.of(peer)

    def of(self, peer: int) -> Offset | None:
        """The peer's offset: the sample of least delay among its last `keep` (None: none)."""
        kept = self._samples.get(peer)
        if not kept:
            return None
        delay, offset, error = min(kept)
        return Offset(offset, error, delay, self._counts[peer])

    def forget(self, peer: int) -> None:
        """The peer restarted: its clock may have been set since; measure it again."""
        self._samples.pop(peer, None)

    def peers(self) -> dict[int, Offset]:
        return {p: o for p in sorted(self._samples) if (o := self.of(p)) is not None}
