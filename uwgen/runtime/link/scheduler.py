"""The link scheduler: owns the link budget and decides what goes out next.

The acoustic link carries a few hundred bytes per second, so what cannot go out now must wait in
*our* queues, where policy can act on it (DESERT's own queue is unbounded and policy-blind). Each
channel (one topic or service id) has a LinkPolicy, turned into small policy objects:

- a queue discipline: `latest` keeps only the newest message (a newer one supersedes the waiting
  one), `fifo` keeps `depth` messages and drops the OLDEST on overflow;
- a rate limit: at most `rate` messages per second leave the channel (a token bucket of depth 1,
  or a frame's worth under TDMA: `burst`);
- a time-to-live: a message older than `ttl` when it would be sent is dropped, never sent stale;
- a priority and no starvation: each message served moves its channel's claim 1 / (priority
  + 1) later in virtual time and the earliest claim goes next (see `claim`), so under
  saturation every channel with traffic is served in proportion to priority + 1 and none
  starves. A `strict` channel (manifest key `strict`) goes before all others whenever ready.

`next_payload(now)` is called by the connection only when it may write (pull, not push). Every
message offered is accounted for exactly once:

    offered == sent + superseded + overflow + expired + too_large + invalid + protect_failed + queued

where `queued` counts waiting messages including one being sent in fragments. `rate_limited` is
informational: messages that were held back at least once by the rate limit while the link was free.

With a splitter (uwgen.runtime.wire.fragment.Fragmenter.split), every payload longer than `fec_over`
bytes (one packet's worth) is split when it starts to go out, so that no frame crosses a packet
(a lost packet then never damages a frame outside it); a channel added `whole` (rmw_desert
entries, which its nodes must read unsplit) is never split. On a channel whose policy asks for
`repair` fragments, that many repair fragments follow the data fragments (wire format section
11). Fragments then leave one per `next_payload` call, so a higher-priority
channel can still get in between. A message being sent in fragments is finished even if a newer
one arrives (it is not superseded) or its ttl passes: abandoning it would waste what already went.

Security (uwgen.security.guard.LinkGuard): `protect(key, payload)` turns a message into its
protected form at the moment it is taken to be sent (in `next_payload`, before it is split), never
while it is only being considered: a message that waits behind others is sealed when it finally
leaves, so its sequence number is never older than the frames sent before it (a receiver's replay
window would refuse a frame sealed early and sent after more than a window of newer ones).
`overhead(key)` is the most protection may add, counted in the size check of `offer` and, for a
message not sealed yet, in the room it needs in a packet-aligned write. A message that cannot be
protected is dropped (`protect_failed`), never sent in the clear.
"""
from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.link.channels import DROP_REASONS  # noqa: F401 (callers read it from here)
from uwgen.runtime.link.channels import Channel, Message, expiry_for, queue_for, rate_for
from uwgen.runtime.link.filling import first_keeping_best
from uwgen.runtime.wire.framing import MAX_PAYLOAD
from uwgen.runtime.stats import log_count

log = logging.getLogger("uwgen.link.scheduler")
FILL_TAIL = 2     # filling chooses among the fitting messages once the room left is below two
                  # of the longest of them: earlier, claim order alone decides (fair shares)

Splitter = Callable[..., list[bytes]]          # (payload) or (payload, repair)
Protect = Callable[[int, bytes], bytes]
Stamp = Callable[[int, bytes, float, float], bytes]


class LinkScheduler:
    """Channels with policies; `offer()` from any thread, `next_payload()` from the connection.

    `splitter` (optional) fragments payloads over 255 bytes, and `max_message` is the largest it
    accepts; without a splitter such payloads are refused (counted too_large, logged).
    """

    def __init__(self, clock: Clock = SYSTEM_CLOCK, *, splitter: Splitter | None = None,
                 max_message: int = MAX_PAYLOAD, name: str = "link",
                 fec_over: int = MAX_PAYLOAD, max_message_for: Callable[[int], int] | None = None,
                 protect: Protect | None = None, overhead: Callable[[int], int] | None = None,
                 measure: Callable[[bytes], int] = len, stamp: Stamp | None = None,
                 burst: float = 0.0):
        self.clock = clock
        self.burst = burst             # s between the link's write windows (rate buckets' depth)
        self.stamp = stamp             # (key, payload, born, now) -> payload with its head
        self.measure = measure         # what a payload costs in the room `next_payload` fills
        self.splitter = splitter
        self.protect = protect
        self.overhead = overhead
        self.max_message = max_message if splitter is not None else MAX_PAYLOAD
        self.fec_over = fec_over
        self._max_message_for = max_message_for
        self.name = name
        self._channels: dict[int, Channel] = {}
        self._order: list[Channel] = []            # strict first, by priority, then key
        self._last_served: dict[int, int] = {}     # strict priority -> key served last (turns)
        self._turns = 0
        self._vtime = 0.0                          # the claim served last (virtual time)
        self._lock = threading.Lock()

    # -- configuration -------------------------------------------------------------------------

    def add_channel(self, key: int, policy: LinkPolicy, name: str | None = None, *,
                    whole: bool = False) -> None:
        """`whole`: never fragment this channel's payloads (rmw_desert peers read them as they
        are); otherwise, with a splitter, a payload longer than one packet is fragmented so
        that no frame crosses a packet."""
        if key in self._channels:
            raise ValueError(f"channel {key} already added")
        ch = Channel(key=key, policy=policy, name=name or f"channel {key}", queue_kind=queue_for(policy),
                     rate=rate_for(policy, self.burst), expiry=expiry_for(policy), max_message=self.max_message)
        if policy.repair and (self.splitter is None or whole):
            raise ValueError(f"channel {key}: repair fragments need fragments (a fragment_id) "
                             "and a channel that may be fragmented")
        # a message may be cut across two packets (wire format 14.2): never a reliable one
        # (re-sent whole) nor one that must reach an rmw_desert peer whole
        ch.cuttable = policy.cut and not policy.reliable and not whole
        if self.splitter is not None and not whole:
            ch.split_over = min(self.fec_over, MAX_PAYLOAD)
            if self._max_message_for is not None:
                ch.max_message = self._max_message_for(policy.repair)
        with self._lock:
            self._channels[key] = ch
            self._order = sorted(self._channels.values(),
                                 key=lambda c: (not c.policy.strict, -c.priority, c.key))

    # -- producer side -------------------------------------------------------------------------

    def offer(self, key: int, payload: bytes, published: float | None = None) -> bool:
        """Queue one unframed payload; False (and a counted drop) if it can never be sent.
        `published`: when it was published, on this scheduler's clock (docs/seams.md
        section 4); its ttl runs from then, not from now. None: now."""
        ch = self._channel(key)
        now = self.clock.now()
        with self._lock:
            c = ch.counters
            c.inc("offered")
            n = len(payload) + (self.overhead(key) if self.overhead and payload else 0)
            if n == 0:
                log_count(log, logging.ERROR, c.inc("invalid"), "[%s] %s: refused an empty payload",
                          self.name, ch.name)
                return False
            if n > ch.max_message:
                why = ("set fragment_id in the manifest to fragment it" if self.splitter is None
                       else f"the most that can be fragmented is {ch.max_message} bytes")
                log_count(log, logging.ERROR, c.inc("too_large"),
                          "[%s] %s: refused a %d-byte payload: a frame holds at most %d bytes; %s",
                          self.name, ch.name, n, MAX_PAYLOAD, why)
                return False
            born = now if published is None else min(now, published)
            for _, reason in ch.queue_kind.push(ch.queue, Message(bytes(payload), born)):
                c.inc(reason)
            return True

    def withdraw(self, key: int, payload: bytes) -> bool:
        """Take back a queued payload that has not started to leave (the first equal one):
        its sender no longer needs it sent (a command's copy whose answer came meanwhile).
        False when none waits (it left, or was never queued); counted `withdrawn`."""
        with self._lock:
            ch, msg = self._queued(key, payload)
            if msg is None:
                return False
            ch.queue.remove(msg)
            ch.counters.inc("withdrawn")
            return True

    def waiting(self, key: int, payload: bytes) -> bool:
        """True while a payload equal to `payload` waits in channel `key`, not yet started to
        leave (a command's copy is not queued behind an equal one that has not left)."""
        with self._lock:
            return self._queued(key, payload)[1] is not None

    def _queued(self, key: int, payload: bytes) -> tuple[Channel | None, Message | None]:
        """Channel `key` and the first message in its queue equal to `payload` (lock held)."""
        ch = self._channels.get(key)
        msg = None if ch is None else next((m for m in ch.queue if m.payload == payload), None)
        return ch, msg

    # -- consumer side (the connection, when it may write) -------------------------------------

    def next_payload(self, now: float | None = None, max_size: int | None = None,
                     exclude: int | None = None, *, fill: bool = False,
                     packet: int | None = None,
                     extra: Callable[[int], int] | None = None,
                     cut: Callable[[int, bytes], bool] | None = None,
                     measure: Callable[[bytes], int] | None = None) -> tuple[int, bytes] | None:
        """The payload (at most 255 bytes) to send now, with its channel key; None if none may go.

        With `max_size` (the room left in a packet-aligned write), only a channel whose next
        payload is at most that long is served: the best such one, so the room is filled without
        taking out a message that would have to wait, whole, for the next write. Channel
        `exclude` is skipped (its next message is held for the next write: keep its order).
        `fill` (with `max_size`): at the tail of a packet (less room than two of the longest
        fitting messages, FILL_TAIL), of the channels that fit, the first in claim order that
        still lets `max_size` be filled as well as any choice of their next messages could
        (uwgen.runtime.link.filling); claims move only for what is served, so a channel passed over
        goes first in the next packet: `packet` (the packer's count of the packet being
        filled) lets a channel passed over at one packet's tail go before any better fit at
        a later packet's tail, when nothing served it in between. `extra(key)`: bytes a
        message of channel `key` adds to the packet besides itself (a part it brings, T),
        counted into its size. Filling from the start would let message sizes decide
        shares (measured: the priority-10 topic of envelope_bench's table 3 fell from 0.18 to
        0.15 of the link); the tail alone costs it nothing measurable.
        `cut(key, payload)`: the message will be cut to end the packet (wire format 14.2):
        only a cuttable channel whose next message is whole (not a fragment, not one to be
        split) and that `cut` accepts is served, in claim order. `measure` (with `max_size`):
        what a payload adds to the packet being filled, instead of the scheduler's own measure
        (a packer knows that a message joining a run costs its body alone).
        """
        now = self.clock.now() if now is None else now
        with self._lock:
            self._expire(now)
            while True:
                ch = self._pick(now, max_size, exclude, fill and max_size is not None, packet,
                                extra, cut, measure)
                if ch is None:
                    return None
                if self._seal_head(ch, now):   # sealed now, as it leaves (or nothing to seal)
                    return ch.key, self._take(ch, now)

    def next_ready_time(self, now: float | None = None) -> float | None:
        """When `next_payload` will next have something (>= now), or None if every queue is empty."""
        now = self.clock.now() if now is None else now
        with self._lock:
            times = [t for ch in self._order if (t := ch.ready_at(now)) is not None]
            return min(times) if times else None

    # -- accounting ----------------------------------------------------------------------------

    def stats(self) -> dict[int, dict[str, int]]:
        with self._lock:
            return {ch.key: {**ch.counters.as_dict(), "queued": ch.queued} for ch in self._order}

    # -- internals -----------------------------------------------------------------------------

    def _channel(self, key: int) -> Channel:
        try:
            return self._channels[key]
        except KeyError:
            raise KeyError(f"[{self.name}] no channel {key}; add_channel() it first "
                           f"(known: {sorted(self._channels)})") from None

    def _expire(self, now: float) -> None:
        for ch in self._order:
            q = ch.queue
            # Messages are queued in offer order, so the stale ones are at the head.
            while q and ch.expiry.expired(q[0], now):
                q.popleft()
                ch.counters.inc("expired")

    def _pick(self, now: float, max_size: int | None = None, exclude: int | None = None,
              fill: bool = False, packet: int | None = None,
              extra: Callable[[int], int] | None = None,
              cut: Callable[[int, bytes], bool] | None = None,
              measure: Callable[[bytes], int] | None = None) -> Channel | None:
        """The channel to serve: a ready strict channel of the highest priority (in turns among
        equals), else the ready channel with the earliest claim (see `claim`); with `fill`, the
        first in claim order whose message keeps the best fill of `max_size` reachable."""
        strict: list[Channel] = []
        best: Channel | None = None
        best_rank: tuple = ()
        fitting: list[tuple[tuple, Channel, int]] = []
        for ch in self._order:
            t = ch.ready_at(now)
            if t is None or ch.key == exclude:
                continue
            if t > now:
                if not ch.queue[0].rate_held:
                    ch.queue[0].rate_held = True
                    ch.counters.inc("rate_limited")
                continue
            size = (self._next_size(ch, measure) + (extra(ch.key) if extra is not None else 0)
                    if max_size is not None else 0)
            if max_size is not None and size > max_size:
                continue
            if cut is not None and not self._cuttable(ch, cut):
                continue
            if ch.policy.strict:
                if not strict or ch.priority == strict[0].priority:
                    strict.append(ch)
                continue
            rank = (self.claim(ch), -ch.priority, ch.turn, ch.key)
            if fill:
                fitting.append((rank, ch, size))
            if best is None or rank < best_rank:
                best, best_rank = ch, rank
        if fill and not strict and len(fitting) > 1 and max_size < FILL_TAIL * max(f[2] for f in fitting):
            fitting.sort(key=lambda f: f[0])
            first = fitting[0][1]
            if packet is not None and first.passed_in is not None and first.passed_in != packet:
                # passed over at an earlier packet's tail and not served since (a strict
                # topic may take every packet's head): it goes now, before any better fit,
                # or a tail with room for one message would serve only the ids that fill it
                chosen_fill = first
            else:
                i = first_keeping_best([f[2] for f in fitting], max_size)
                chosen_fill = fitting[i][1] if i is not None else best
                if packet is not None:
                    for _, ch, _ in fitting[:i or 0]:
                        if ch.passed_in is None:
                            ch.passed_in = packet
        else:
            chosen_fill = best
        if strict:
            last = self._last_served.get(strict[0].priority)
            chosen = next((ch for ch in strict if last is not None and ch.key > last), strict[0])
            self._last_served[chosen.priority] = chosen.key
        elif best is not None:
            # Virtual time is the earliest claim of the channels that could go (`best`), also
            # when filling serves a later one: those passed over keep their standing.
            self._vtime = self.claim(best)
            chosen = chosen_fill if chosen_fill is not None else best
            chosen.tag = self.claim(chosen) + 1.0 / chosen.weight
        else:
            return None
        self._turns += 1
        chosen.passed_in = None
        chosen.turn = self._turns        # equal claims: the one served longest ago goes first
        return chosen

    def _cuttable(self, ch: Channel, cut: Callable[[int, bytes], bool]) -> bool:
        """Whether the channel's next message may be cut now (see `next_payload`)."""
        if not ch.cuttable or ch.in_progress is not None:
            return False
        msg = ch.queue[0]
        extra = self.overhead(ch.key) if self.overhead is not None and not msg.sealed else 0
        return len(msg.payload) + extra <= ch.split_over and cut(ch.key, msg.payload)

    def claim(self, ch: Channel) -> float:
        """When a channel is due in virtual time (start-time fair queuing): each message served
        moves its channel's claim 1 / weight later, weight = priority + 1 (priorities below 0
        weigh 1); a channel that waited, idle or held back, claims no earlier than the claim
        served last. The earliest claim is served next, so while a channel waits every other
        channel served moves behind it: its standing grows with the service the others get
        (the intent of Goby3's DynamicBuffer, whose value grows with the time a queue waited,
        scaled by its priority), and under saturation each channel with traffic is served in
        proportion to its weight, however many messages one packet takes at one instant."""
        return max(ch.tag, self._vtime)

    def _seal_head(self, ch: Channel, now: float) -> bool:
        """Stamp (reliability head: message number, age) and protect the channel's next
        message as it is taken to be sent; False (the message dropped and counted, never
        sent in the clear) when it cannot be protected."""
        if (self.protect is None and self.stamp is None) or ch.in_progress is not None \
                or ch.queue[0].sealed:
            return True
        msg = ch.queue[0]
        try:
            payload = msg.payload
            if self.stamp is not None:
                payload = self.stamp(ch.key, payload, msg.offered_at, now)
            msg.payload = self.protect(ch.key, payload) if self.protect is not None else payload
            msg.sealed = True
            return True
        except Exception as exc:  # SecurityError: the guard cannot protect it
            ch.queue.popleft()
            log_count(log, logging.ERROR, ch.counters.inc("protect_failed"),
                      "[%s] %s: message dropped, cannot be protected: %s", self.name, ch.name, exc)
            return False

    def _next_size(self, ch: Channel, measure: Callable[[bytes], int] | None = None) -> int:
        """Length of the payload `_take` would return for this channel (a message about to be
        split: its first fragment, at most one packet's worth), as `measure` (default: the
        scheduler's) counts it."""
        measure = measure or self.measure
        if ch.in_progress is not None:
            return measure(ch.in_progress[0])
        msg = ch.queue[0]
        n = len(msg.payload)
        extra = self.overhead(ch.key) if self.overhead is not None and not msg.sealed else 0
        if n + extra > ch.split_over:
            return self.fec_over
        return measure(msg.payload) + extra   # the most sealing it (as it leaves) may add

    def _take(self, ch: Channel, now: float) -> bytes:
        c = ch.counters
        if ch.in_progress is None:
            msg = ch.queue.popleft()
            ch.rate.took(now)
            if len(msg.payload) <= ch.split_over:
                c.inc("sent")
                return msg.payload
            assert self.splitter is not None
            repair = ch.policy.repair
            ch.in_progress = deque(self.splitter(msg.payload, repair) if repair else self.splitter(msg.payload))
        part = ch.in_progress.popleft()
        c.inc("fragments_sent")
        if not ch.in_progress:
            ch.in_progress = None
            c.inc("sent")
        return part
