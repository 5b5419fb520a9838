"""Outstanding service calls of the calling side: sequence numbers, timeouts, late answers.

A bridged call crosses the acoustic link as `[2, id, seq, ...]` and comes back as
`[3, id, seq, ...]`. This table decides the seq of each call, remembers which calls are
still waiting, expires them at their deadline, and classifies every response that does
not complete a waiting call (late, duplicate or unknown) so that it is counted, never
silently dropped and never delivered to the wrong caller.

It is pure bookkeeping with an injectable clock: no ROS, no threads (the bridge calls it
from its executor thread only).

Sequence numbers are per service id, drawn from that service's range (`first..last`,
both included). Each id starts at a random value in its range so that responses meant for
a previous run of the bridge (still in flight over a slow link) do not match a new call;
they then count up, wrapping from `last` to `first`, skipping any seq still outstanding.
The default range is 0..seq_modulus-1 (2**16 values, so a seq costs at most 3 bytes on the
wire); `set_seq_range()` narrows it for one service, e.g. to 1..999 toward rmw_desert
servers (RMW_DESERT_SEQ_RANGE), whose own clients pick seqs 0..999. With `reuse_after`,
a seq finished less than that many seconds ago is not given out again while another free
one exists (actions: a repeated goal must never be mistaken for a new one).
"""
from __future__ import annotations

import random
from collections import OrderedDict
from dataclasses import asdict, dataclass, field
from typing import Any

from uwgen.runtime.clock import Clock, SYSTEM_CLOCK

DEFAULT_SEQ_MODULUS = 1 << 16
RMW_DESERT_SEQ_RANGE = (1, 999)   # what a call toward an rmw_desert-profile service uses
DEFAULT_MAX_OUTSTANDING = 32
DEFAULT_MEMORY = 256

# Outcomes remembered for finished calls, to classify responses that come after them.
COMPLETED = "completed"
TIMED_OUT = "timed_out"
ABANDONED = "abandoned"


class CallTableFull(Exception):
    """Too many calls of one service are outstanding; the new call is refused (and counted)."""


@dataclass
class PendingCall:
    service_id: int
    seq: int
    started: float
    deadline: float
    token: Any = None   # whatever the bridge needs to finish the call (an rclpy Future)

    def age(self, now: float) -> float:
        return now - self.started


@dataclass
class CallStats:
    """Counters of one service on the calling side (all monotonic)."""

    calls: int = 0        # calls accepted into the table
    refused: int = 0      # calls refused: too many outstanding
    abandoned: int = 0    # calls given up before a response (e.g. the link refused the request)
    completed: int = 0    # responses that completed an outstanding call
    timeouts: int = 0     # calls that got no response before their deadline
    late: int = 0         # responses for a call that had already timed out or been abandoned
    duplicate: int = 0    # further responses for a call that was already completed
    unknown: int = 0      # responses whose seq this table never issued (or has forgotten)
    latencies: list[float] = field(default_factory=list, repr=False)

    def as_dict(self) -> dict[str, int]:
        d = asdict(self)
        d.pop("latencies")
        d["outstanding"] = self.calls - self.completed - self.timeouts - self.abandoned
        return d


class CallTable:
    """Calls waiting for their response, keyed by (service id, seq)."""

    def __init__(self, clock: Clock = SYSTEM_CLOCK, *, rng: random.Random | None = None,
                 seq_modulus: int = DEFAULT_SEQ_MODULUS,
                 max_outstanding: int = DEFAULT_MAX_OUTSTANDING,
                 memory: int = DEFAULT_MEMORY, keep_latencies: int = 1000,
                 reuse_after: float = 0.0):
        if seq_modulus < 2:
            raise ValueError("seq_modulus must be at least 2")
        if not 1 <= max_outstanding < seq_modulus:
            raise ValueError("max_outstanding must be between 1 and seq_modulus - 1")
        self._clock = clock
        self._rng = rng if rng is not None else random.SystemRandom()
        self._modulus = seq_modulus
        self._max_outstanding = max_outstanding
        self._memory = memory
        self._keep_latencies = keep_latencies
        self._next: dict[int, int] = {}
        self._ranges: dict[int, tuple[int, int]] = {}
        self._pending: dict[int, dict[int, PendingCall]] = {}
        self._finished: dict[int, OrderedDict[int, str]] = {}
        self._freed_at: dict[int, dict[int, float]] = {}
        self._reuse_after = reuse_after
        self._stats: dict[int, CallStats] = {}

    # -- configuration -----------------------------------------------------------------

    def set_seq_range(self, service_id: int, first: int, last: int) -> None:
        """Give calls of `service_id` seqs in first..last (both included).

        The range must hold more seqs than can be outstanding at once, so that allocation
        always finds a free one. Calls already outstanding keep their seqs; the next call
        starts at a random value in the new range.
        """
        if not 0 <= first <= last:
            raise ValueError(f"service id {service_id}: seq range {first}..{last} is empty "
                             "or negative")
        if last - first + 1 <= self._max_outstanding:
            raise ValueError(f"service id {service_id}: seq range {first}..{last} must hold "
                             f"more than {self._max_outstanding} seqs (the outstanding limit)")
        self._ranges[service_id] = (first, last)
        self._next.pop(service_id, None)

    def seq_range(self, service_id: int) -> tuple[int, int]:
        """The seqs calls of `service_id` get, as (first, last), both included."""
        return self._ranges.get(service_id, (0, self._modulus - 1))

    # -- calls -------------------------------------------------------------------------

    def begin(self, service_id: int, timeout: float, token: Any = None) -> PendingCall:
        """Register a new call and give it a seq. Raises CallTableFull (counted)."""
        stats = self.stats_of(service_id)
        pending = self._pending.setdefault(service_id, {})
        if len(pending) >= self._max_outstanding:
            stats.refused += 1
            raise CallTableFull(
                f"service id {service_id}: {len(pending)} calls already outstanding "
                f"(limit {self._max_outstanding})")
        seq = self._allocate(service_id, pending)
        now = self._clock.now()
        call = PendingCall(service_id, seq, now, now + timeout, token)
        pending[seq] = call
        # A seq reused after a wrap is no longer "finished".
        self._finished.setdefault(service_id, OrderedDict()).pop(seq, None)
        stats.calls += 1
        return call

    def _allocate(self, service_id: int, pending: dict[int, PendingCall]) -> int:
        first, last = self.seq_range(service_id)
        size = last - first + 1
        seq = self._next.get(service_id)
        if seq is None or not first <= seq <= last:
            seq = first + self._rng.randrange(size)
        freed = self._freed_at.get(service_id, {})
        now = self._clock.now()
        fallback = None
        for _ in range(size):   # the range holds more seqs than max_outstanding: one is free
            if seq not in pending:
                if now - freed.get(seq, -float("inf")) >= self._reuse_after:
                    break
                if fallback is None:
                    fallback = seq                 # free, but finished only recently
            seq = first + (seq - first + 1) % size
        else:
            seq = fallback
        self._next[service_id] = first + (seq - first + 1) % size
        return seq

    def complete(self, service_id: int, seq: int) -> PendingCall | None:
        """A response arrived. Returns the call it completes, or None (then it was counted
        as late, duplicate or unknown and must be dropped)."""
        stats = self.stats_of(service_id)
        call = self._pending.get(service_id, {}).pop(seq, None)
        if call is not None:
            stats.completed += 1
            if len(stats.latencies) < self._keep_latencies:
                stats.latencies.append(call.age(self._clock.now()))
            self._remember(service_id, seq, COMPLETED)
            return call
        outcome = self._finished.get(service_id, {}).get(seq)
        if outcome == COMPLETED:
            stats.duplicate += 1
        elif outcome in (TIMED_OUT, ABANDONED):
            stats.late += 1
        else:
            stats.unknown += 1
        return None

    def finished(self, service_id: int, seq: int) -> str | None:
        """How the last call of this seq ended, while it is remembered (completed, timed out,
        abandoned), or None: no call of this seq finished lately."""
        return self._finished.get(service_id, {}).get(seq)

    def get(self, service_id: int, seq: int) -> PendingCall | None:
        """The outstanding call of this seq, left outstanding (e.g. to move its deadline)."""
        return self._pending.get(service_id, {}).get(seq)

    def pending(self, service_id: int) -> list[PendingCall]:
        """The outstanding calls of one service, in no particular order."""
        return list(self._pending.get(service_id, {}).values())

    def abandon(self, service_id: int, seq: int) -> PendingCall | None:
        """Give up a call before its response (e.g. the request could not be queued)."""
        call = self._pending.get(service_id, {}).pop(seq, None)
        if call is not None:
            self.stats_of(service_id).abandoned += 1
            self._remember(service_id, seq, ABANDONED)
        return call

    def expire(self) -> list[PendingCall]:
        """Remove and return every call whose deadline has passed, oldest deadline first."""
        now = self._clock.now()
        expired: list[PendingCall] = []
        for service_id, pending in self._pending.items():
            for seq, call in list(pending.items()):
                if call.deadline <= now:
                    del pending[seq]
                    self.stats_of(service_id).timeouts += 1
                    self._remember(service_id, seq, TIMED_OUT)
                    expired.append(call)
        expired.sort(key=lambda c: c.deadline)
        return expired

    def _remember(self, service_id: int, seq: int, outcome: str) -> None:
        if self._reuse_after:
            self._freed_at.setdefault(service_id, {})[seq] = self._clock.now()
        finished = self._finished.setdefault(service_id, OrderedDict())
        finished[seq] = outcome
        finished.move_to_end(seq)
        while len(finished) > self._memory:
            finished.popitem(last=False)

    # -- queries -------------------------------------------------------------------------

    def next_deadline(self) -> float | None:
        deadlines = [c.deadline for p in self._pending.values() for c in p.values()]
        return min(deadlines) if deadlines else None

    def outstanding(self, service_id: int | None = None) -> int:
        if service_id is not None:
            return len(self._pending.get(service_id, {}))
        return sum(len(p) for p in self._pending.values())

    def stats_of(self, service_id: int) -> CallStats:
        return self._stats.setdefault(service_id, CallStats())

    def stats(self) -> dict[int, dict[str, int]]:
        return {sid: s.as_dict() for sid, s in sorted(self._stats.items())}
