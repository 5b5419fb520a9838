"""When a turn must be over (mode `turns`: docs/wire-format.md section 16, rules 2 and 3).

Both sides compute the same bounds from the manifest alone (range, bitrate, DESERT's period
and packet size), so a leader and a follower built from one manifest always agree: the
follower writes its turn's packets only inside a window that starts when it heard its grant
(or its notice's wait ended), and the leader knows by when the last of them has started
arriving, whatever was lost. The leader takes the turn back then (or earlier: on the end),
so a lost grant or a lost answer costs the wait for what could still come, no more.

Every bound is a worst case of its parts:
- a packet written at t starts on the air by t + period (DESERT's tick) + LISTEN (its MAC's
  listen), ends air time later, and has reached every side by then + the range's delay:
  `one_way`;
- a side writes within REACT of the event that allows it (its connection thread's wake-up),
  then one packet per pacer interval;
- a notice heard at h, d packets before its grant, lets its follower start at
  h + d x interval + period + air + LISTEN (the grant's packet has ended everywhere by then);
  a follower that heard one notice only takes it for the first (d = NOTICES), and the
  leader's bound counts on that.
"""
from __future__ import annotations

from collections import deque
from statistics import median

from uwgen.manifest.mac import LISTEN, air_time
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.pacing import DEFAULT_MARGIN

REACT = 0.1     # s: from the packet that gives a side its turn to its first write (thread wake-up, loaded host)
NOTICES = 2     # notices before a grant, one a packet (section 16, rule 1)
ROUNDS_KEPT = 9     # own turns' spacings a measured round is the median of (Rounds)
ROUNDS_NEEDED = 3   # ... before it stands for the first guess


class TurnTiming:
    """The bounds of one manifest's turns (module doc)."""

    def __init__(self, config: MacConfig, link: LinkConfig, margin: float = DEFAULT_MARGIN):
        self.period = link.period
        self.air = air_time(link.max_read_length, config.bitrate)
        self.bitrate = config.bitrate
        self.interval = max(link.period * (1 + margin), self.air)
        self.delay = config.delay
        self.one_way = self.period + LISTEN + self.air + self.delay

    def notice_start(self, heard_at: float, distance: int = 1) -> float:
        """Follower: when a turn announced by a notice heard at `heard_at`, `distance`
        packets before its grant, starts if the grant is lost (the grant's packet has ended
        everywhere by then: the leader writes no grant later than `distance` intervals and
        REACT after the notice)."""
        return heard_at + distance * self.interval + self.period + self.air + LISTEN

    def window(self, start: float, count: int) -> float:
        """Follower: the last moment it may write a packet of a `count`-packet turn that it
        could start at `start`."""
        return start + REACT + (count - 1) * self.interval

    def arriving_by(self, written_by: float) -> float:
        """When a packet written by `written_by` has started arriving at every side."""
        return written_by + self.period + LISTEN + self.delay

    def grant_deadline(self, granted_at: float, count: int, noticed_at: float | None = None) -> float:
        """Leader: by when every packet of the turn it granted at `granted_at` (its last
        notice written at `noticed_at`, if any) has started arriving, if it hears none of
        them. A follower that heard that notice alone takes it for the first."""
        start = granted_at + self.one_way
        if noticed_at is not None:
            start = max(start, self.notice_start(noticed_at + self.one_way, NOTICES))
        return self.arriving_by(self.window(start, count))

    def rest_deadline(self, heard_start: float, rest: int) -> float:
        """Leader: by when `rest` more packets of an answer have started arriving, after one
        that started arriving at `heard_start` (each written at most an interval after the
        one before, a late wake-up at most REACT)."""
        return heard_start + rest * self.interval + REACT + self.period + LISTEN

    def packet_air(self, nbytes: int | None) -> float:
        """Air time of a packet of `nbytes` as DESERT sent it (None: not known, 0: the
        arrival's start is then taken as its end, later than it was)."""
        return 0.0 if nbytes is None else air_time(nbytes, self.bitrate)


class RoundTrip:
    """Smoothed round trip of a turn (RFC 6298's mean), from a first guess: what a round of
    turns takes (TurnMac.cycle), never a timer (those are TurnTiming's bounds)."""

    def __init__(self, first: float):
        self.srtt, self.samples = first, 0

    def sample(self, rtt: float) -> None:
        self.srtt = rtt if self.samples == 0 else 0.875 * self.srtt + 0.125 * rtt
        self.samples += 1


class Rounds:
    """A round as one side lives it: the time from the start of one of its own turns to the
    start of the next (its turn, the leader's and every other follower's, and the trips
    between). The median of the last ROUNDS_KEPT spacings, so a turn lost now and then (a
    spacing of two rounds) does not move it; None until ROUNDS_NEEDED were seen."""

    def __init__(self):
        self._last: float | None = None
        self._spacings: deque[float] = deque(maxlen=ROUNDS_KEPT)

    def started(self, now: float) -> None:
        """An own turn's first packet is being built at `now`."""
        if self._last is not None:
            self._spacings.append(now - self._last)
        self._last = now

    def next_start(self, now: float, length: float) -> float:
        """When the next own turn is likely to start, rounds of `length`: a round after the
        last one started, not before `now`."""
        return now if self._last is None else max(now, self._last + length)

    def measured(self) -> float | None:
        spacings = list(self._spacings)       # read on another thread (the bridge's)
        return median(spacings) if len(spacings) >= ROUNDS_NEEDED else None


def late_by(missed: tuple[int, float, float] | None, sender: int, start: float) -> float | None:
    """The leader: by how much a packet of `sender` that started arriving at `start` came
    after the bound at which the leader took that follower's last turn back (`missed`:
    follower, bound, the turn's span), when it came within a span of it: a late answer (the
    manifest's range or bitrate is not the real one); else None."""
    if missed is None or sender != missed[0]:
        return None
    _who, deadline, span = missed
    return start - deadline if deadline < start < deadline + span else None

