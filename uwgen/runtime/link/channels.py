"""A link channel and its policy objects (uwgen.runtime.link.scheduler serves the channels).

Each channel (one topic, service or action id) has a LinkPolicy, turned into small policy
objects: a queue discipline (`latest` keeps only the newest message, `fifo` keeps `depth` and
drops the oldest), a rate limit (a token bucket, of depth 1 unless the link writes in bursts)
and an expiry (`ttl`). Add new
kinds here, not if-chains in the scheduler.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.stats import Counters
from uwgen.runtime.wire.framing import MAX_PAYLOAD

CHANNEL_COUNTERS = ("offered", "sent", "superseded", "overflow", "expired", "too_large", "invalid",
                    "rate_limited", "fragments_sent", "protect_failed", "withdrawn")
DROP_REASONS = ("superseded", "overflow", "expired", "too_large", "invalid", "protect_failed")


@dataclass
class Message:
    payload: bytes
    offered_at: float
    rate_held: bool = False
    sealed: bool = False        # protected already (or nothing to protect)


# -- policy objects (one of each per channel; add new kinds here, not if-chains below) -----------

class QueueDiscipline(Protocol):
    def push(self, queue: deque[Message], msg: Message) -> list[tuple[Message, str]]:
        """Add msg; return the messages this pushed out, each with its counter name."""


class LatestQueue:
    """Keep only the newest message: commands and poses, where an old value is worthless."""

    def push(self, queue: deque[Message], msg: Message) -> list[tuple[Message, str]]:
        dropped = [(m, "superseded") for m in queue]
        queue.clear()
        queue.append(msg)
        return dropped


class FifoQueue:
    """Keep up to `depth` messages in order; on overflow the oldest goes (it is the stalest)."""

    def __init__(self, depth: int):
        if depth < 1:
            raise ValueError(f"fifo depth must be at least 1, got {depth}")
        self.depth = depth

    def push(self, queue: deque[Message], msg: Message) -> list[tuple[Message, str]]:
        queue.append(msg)
        dropped = []
        while len(queue) > self.depth:
            dropped.append((queue.popleft(), "overflow"))
        return dropped


class RateLimit(Protocol):
    def ready_at(self, now: float) -> float:
        """Earliest time (>= now) a message may leave."""

    def took(self, now: float) -> None:
        """A message left at `now`."""


class Unlimited:
    def ready_at(self, now: float) -> float:
        return now

    def took(self, now: float) -> None:
        pass


class TokenBucket:
    """At most `rate` messages per second: a bucket of `depth` tokens refilled at `rate`.
    Depth 1 (the default): no bursts, messages at least 1 / rate apart. A link that may
    write only in a slot once a frame (TDMA) gives its channels a frame's worth of depth
    (`rate_for`'s `burst`), so the rate holds on average over the frame and its slot
    carries what the rest of the frame saved, each message built fresh in the slot."""

    def __init__(self, rate: float, depth: float = 1.0):
        if rate <= 0:
            raise ValueError(f"rate must be positive, got {rate}")
        self.interval = 1.0 / rate
        self.depth = max(1.0, depth)
        self._tokens, self._at = self.depth, float("-inf")

    def _level(self, now: float) -> float:
        return min(self.depth, self._tokens + (now - self._at) / self.interval)

    def ready_at(self, now: float) -> float:
        # Within a nanosecond counts as on time: 0.4 + 0.2 must not miss a poll at 0.6.
        missing = 1.0 - self._level(now)
        return now if missing * self.interval <= 1e-9 else now + missing * self.interval

    def took(self, now: float) -> None:
        self._tokens, self._at = max(0.0, self._level(now) - 1.0), now


class Expiry(Protocol):
    def expired(self, msg: Message, now: float) -> bool: ...


class NoExpiry:
    def expired(self, msg: Message, now: float) -> bool:
        return False


class Ttl:
    def __init__(self, ttl: float):
        if ttl <= 0:
            raise ValueError(f"ttl must be positive, got {ttl}")
        self.ttl = ttl

    def expired(self, msg: Message, now: float) -> bool:
        return now - msg.offered_at > self.ttl


def queue_for(policy: LinkPolicy) -> QueueDiscipline:
    kinds: dict[str, Callable[[LinkPolicy], QueueDiscipline]] = {
        "latest": lambda p: LatestQueue(),
        "fifo": lambda p: FifoQueue(p.depth),
    }
    if policy.queue not in kinds:
        raise ValueError(f"unknown queue kind {policy.queue!r} (known: {', '.join(kinds)})")
    return kinds[policy.queue](policy)


def rate_for(policy: LinkPolicy, burst: float = 0.0) -> RateLimit:
    """The policy's rate limit; `burst`: seconds between the link's write windows (a TDMA
    frame), whose worth of messages the bucket holds (0: none, depth 1)."""
    return (Unlimited() if policy.rate is None
            else TokenBucket(policy.rate, max(1.0, policy.rate * burst)))


def expiry_for(policy: LinkPolicy) -> Expiry:
    return NoExpiry() if policy.ttl is None else Ttl(policy.ttl)


# -- channels ----------------------------------------------------------------------------------

@dataclass
class Channel:
    key: int
    policy: LinkPolicy
    name: str
    queue_kind: QueueDiscipline
    rate: RateLimit
    expiry: Expiry
    queue: deque[Message] = field(default_factory=deque)
    in_progress: deque[bytes] | None = None      # remaining fragments of the message being sent
    split_over: int = MAX_PAYLOAD                # longer payloads are fragmented
    max_message: int = MAX_PAYLOAD               # longer payloads are refused (too_large)
    counters: Counters = field(default_factory=lambda: Counters(CHANNEL_COUNTERS))
    tag: float = 0.0                             # virtual time when it is next due (see claim)
    turn: int = 0                                # the scheduler's serve count when last served
    passed_in: int | None = None                 # the packet whose tail passed it over, since
                                                 # it was last served (see `_pick`)
    cuttable: bool = False                       # its messages may be cut across two packets

    @property
    def priority(self) -> int:
        return self.policy.priority

    @property
    def weight(self) -> int:
        return max(self.policy.priority, 0) + 1

    @property
    def queued(self) -> int:
        return len(self.queue) + (self.in_progress is not None)

    def ready_at(self, now: float) -> float | None:
        if self.in_progress is not None:
            return now
        if self.queue:
            return self.rate.ready_at(now)
        return None
