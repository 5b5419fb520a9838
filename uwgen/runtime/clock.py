"""Clocks. Everything that waits or schedules takes one, so tests can drive time.

`now()` is monotonic seconds (WallClock: seconds since the UNIX epoch). `ManualClock` only moves when told to.
"""
from __future__ import annotations

import time
from typing import Any, Protocol


class Clock(Protocol):
    def now(self) -> float: ...


class MonotonicClock:
    """The real clock: time.monotonic()."""

    def now(self) -> float:
        return time.monotonic()


class WallClock:
    """Wall time, time.time(): seconds since the UNIX epoch, for times two machines compare
    (the secure link's sync time). Not for measuring intervals: it can jump."""

    def now(self) -> float:
        return time.time()


class ManualClock:
    """A clock for tests: starts at `start` and moves only by `advance()` or `set()`."""

    def __init__(self, start: float = 0.0):
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def advance(self, seconds: float) -> float:
        if seconds < 0:
            raise ValueError("a clock never goes back")
        self._t += seconds
        return self._t

    def set(self, t: float) -> None:
        if t < self._t:
            raise ValueError("a clock never goes back")
        self._t = float(t)


SYSTEM_CLOCK = MonotonicClock()
WALL_CLOCK = WallClock()


def source_time(info: Any) -> float | None:
    """The source timestamp of a message rclpy delivered (its MessageInfo, which a
    subscription callback with two parameters gets: ns since the epoch, stamped by the
    publisher's rmw), in seconds since the epoch; None when there is none."""
    stamp = info.get("source_timestamp") if isinstance(info, dict) else None
    return stamp / 1e9 if isinstance(stamp, int) and stamp > 0 else None
