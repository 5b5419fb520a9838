"""When a fresh TCP connection to DESERT counts as "connected", and when it looks unserved (sans-IO).

A TCP connect succeeding proves little: a DESERT that is shutting down (or restarting) accepts and
closes at once, and DESERT serves one client per port, so a second client (another bridge, a stale
process) is accepted and then never read from nor written to. So:

- a connection is *proven* when bytes arrive from DESERT, or when it stayed open for `probation`
  seconds without EOF or reset. Only then is it reported and counted as connected, and only then
  are writes made (a shutting-down DESERT would drop them);
- a proven connection on which nothing has arrived for `unserved_after` seconds, while we did write,
  may be starving behind another client: warn once, saying what to do. (A far side that simply
  has nothing to say looks the same from here, so it is a warning, not a disconnect.)
"""
from __future__ import annotations

from enum import Enum


class Event(Enum):
    PROVEN = "proven"
    UNSERVED = "unserved"


def reconnect_cap(period: float) -> float:
    """Longest reconnect backoff: one period or 1 s, whichever is larger.

    DESERT drops every byte that arrives for a node with no client, so after a restart each second
    of backoff is a second of traffic lost toward us.
    """
    return max(period, 1.0)


class Probation:
    """The state of one connection: opened -> proven -> (maybe) suspected unserved."""

    def __init__(self, probation: float = 0.3, unserved_after: float = 30.0):
        if probation < 0 or unserved_after <= 0:
            raise ValueError("probation must be >= 0 and unserved_after > 0")
        self.probation = probation
        self.unserved_after = unserved_after
        self.proven = False
        self._opened_at = 0.0
        self._received = False
        self._wrote = False
        self._warned = False

    def opened(self, now: float) -> None:
        self.proven = self._received = self._wrote = self._warned = False
        self._opened_at = now

    def received(self, now: float) -> Event | None:
        self._received = True
        return self._prove()

    def wrote(self) -> None:
        self._wrote = True

    def tick(self, now: float) -> Event | None:
        """Call on every loop turn; returns what just became true (at most once each)."""
        age = now - self._opened_at
        if not self.proven and age >= self.probation - 1e-9:
            return self._prove()
        if (self.proven and not self._received and self._wrote and not self._warned
                and age >= self.unserved_after):
            self._warned = True
            return Event.UNSERVED
        return None

    def deadline(self) -> float | None:
        """When tick() may next have something to say (None: nothing pending)."""
        if not self.proven:
            return self._opened_at + self.probation
        if not self._received and not self._warned:
            return self._opened_at + self.unserved_after
        return None

    def _prove(self) -> Event | None:
        if self.proven:
            return None
        self.proven = True
        return Event.PROVEN
