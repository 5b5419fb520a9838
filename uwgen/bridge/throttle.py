"""Log lines a remote peer can cause, bounded: once, then counted, then a periodic summary.

A peer (or a forger) can send a request per packet; one error line per request would let it
flood the log (1,280 lines in 40 ms were seen). Each kind of event (`key`, e.g. "no_server
/enable") is logged in full the first time, then only counted; every `every` seconds one
summary line per kind says how many more happened since. The counts also live in ~/status.

What a lossy link makes happen in normal operation (a call or a goal that got no answer in
time: the request or its answer was lost) is reported as `expected`, on the WARNING emitter;
everything else (a request nobody serves, bytes that do not decode) on the ERROR one.
"""
from __future__ import annotations

from collections.abc import Callable

from uwgen.runtime.clock import SYSTEM_CLOCK, Clock

SUMMARY_EVERY = 60.0


class LogThrottle:
    """`report(key, text)` from the bridge's thread; `tick()` now and then (a timer)."""

    def __init__(self, emit: Callable[[str], None], clock: Clock = SYSTEM_CLOCK,
                 every: float = SUMMARY_EVERY, warn: Callable[[str], None] | None = None):
        self._emit = emit
        self._warn = warn or emit
        self._expected: set[str] = set()          # keys reported as expected losses
        self._clock = clock
        self.every = every
        self._first: dict[str, str] = {}           # key -> the text logged the first time
        self._since: dict[str, int] = {}           # key -> occurrences not yet summarised
        self.totals: dict[str, int] = {}           # key -> every occurrence
        self._next = clock.now() + every

    def report(self, key: str, text: str, expected: bool = False) -> None:
        """`expected`: a loss the link causes in normal operation (logged as a warning)."""
        self.totals[key] = self.totals.get(key, 0) + 1
        if key not in self._first:
            self._first[key] = text
            if expected:
                self._expected.add(key)
            self._say(key, f"{text} (further ones are counted, summarised every {self.every:g} s)")
            return
        self._since[key] = self._since.get(key, 0) + 1

    def tick(self) -> None:
        now = self._clock.now()
        if now < self._next:
            return
        self._next = now + self.every
        self._summarise()

    def flush(self) -> None:
        """At shutdown: the summary of whatever was counted since the last one."""
        self._summarise()

    def _summarise(self) -> None:
        for key, n in sorted(self._since.items()):
            if n:
                self._say(key, f"{n} more since the last summary ({self.totals[key]} in all) like: "
                               f"{self._first[key]}")
        self._since.clear()

    def _say(self, key: str, text: str) -> None:
        # one call site per emitter: rclpy's logger refuses a call site whose severity changes
        # between calls (ValueError), which took a bridge down mid-goal
        if key in self._expected:
            self._warn(text)
        else:
            self._emit(text)
