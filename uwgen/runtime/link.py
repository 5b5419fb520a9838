"""The link façade every bridge uses: scheduler + fragments + paced DESERT connection + decoder.

    link = Link(host="127.0.0.1", port=4001, config=LinkConfig(max_read_length=64, period=0.2),
                on_payload=callback, fragment_id=250, clock=SYSTEM_CLOCK, name="vehicle")
    link.add_channel(4, LinkPolicy(queue="latest", rate=5, ttl=1.0, priority=10))
    link.offer(4, payload)        # an unframed payload from a generated codec
    link.start(); ...; link.stop()

Outgoing: `offer()` queues a payload on its channel (policy applies there); the connection pulls
payloads when the pacer allows a write, and payloads over 255 bytes leave as fragments (if the
manifest reserves a fragment_id; otherwise they are refused, counted too_large and logged).
Incoming: frames are decoded, fragments reassembled, and `on_payload` receives each complete payload
on the link's thread. Fragments are recognised by their header (kind 0, fragment_id); with
fragment_id None nothing is treated as a fragment.

Security: with a `guard` (uwgen.security.guard.LinkGuard) a whole payload is protected when it
leaves its queue, before it is fragmented, and every whole payload received (after reassembly)
goes through `guard.unprotect`; only what it passes reaches `on_payload`.
"""
from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.connection import Backoff, DesertConnection
from uwgen.runtime.fragment import MAX_COUNT, Fragmenter, Reassembler, fragment_payload_for, is_fragment
from uwgen.runtime.framing import MAX_PAYLOAD
from uwgen.runtime.pacing import DEFAULT_MARGIN
from uwgen.runtime.probation import reconnect_cap
from uwgen.runtime.scheduler import LinkScheduler
from uwgen.runtime.stats import Counters

LINK_COUNTERS = ("payloads_delivered", "nested_fragments")


class Link:
    """One side's link to its DESERT node (see module docstring)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 4000, config: LinkConfig | None = None,
                 on_payload: Callable[[bytes], None] | None = None, fragment_id: int | None = None,
                 clock: Clock = SYSTEM_CLOCK, name: str = "link", *,
                 rng: random.Random | None = None,
                 backoff: Backoff | None = None,
                 stall_timeout: float | None = None,
                 fragment_timeout: float | None = None,
                 max_partial_transfers: int = 8,
                 max_partial_bytes: int = 256 * 1024,
                 max_fragments: int = MAX_COUNT,
                 pace_margin: float = DEFAULT_MARGIN,
                 bitrate: float | None = None,
                 guard: Any = None):
        self.config = config or LinkConfig()
        self.name = name
        self.clock = clock
        self.fragment_id = fragment_id
        self._on_payload = on_payload
        self.guard = guard
        self.counters = Counters(LINK_COUNTERS)
        self._pulled_key: int | None = None       # channel of the payload pulled last
        rng = rng or random.Random()

        self.fragmenter: Fragmenter | None = None
        self.reassembler: Reassembler | None = None
        if fragment_id is not None:
            # A fragment frame fits one DESERT packet, so a lost packet costs whole fragments only.
            self.fragmenter = Fragmenter(fragment_id, rng=rng, max_fragments=max_fragments,
                                         max_payload=fragment_payload_for(self.config.max_read_length))
            # Fragments of one message may be spread out by higher-priority traffic: be patient;
            # memory stays bounded by max_partial_* whatever the timeout.
            timeout = fragment_timeout if fragment_timeout is not None else max(30.0, 60 * self.config.period)
            self.reassembler = Reassembler(fragment_id, clock, timeout=timeout,
                                           max_transfers=max_partial_transfers,
                                           max_bytes=max_partial_bytes, name=name)
        self.scheduler = LinkScheduler(
            clock, name=name,
            splitter=self.fragmenter.split if self.fragmenter else None,
            max_message=self.fragmenter.max_message_size if self.fragmenter else MAX_PAYLOAD,
            fec_over=self.fragmenter.max_payload if self.fragmenter else MAX_PAYLOAD,
            max_message_for=self.fragmenter.max_message_for if self.fragmenter else None,
            protect=guard.protect if guard is not None else None,
            overhead=guard.overhead if guard is not None else None)
        self.connection = DesertConnection(
            host, port, self.config, source=self._source, on_frame=self._on_frame, clock=clock,
            name=name, backoff=backoff or Backoff(maximum=reconnect_cap(self.config.period), rng=rng),
            stall_timeout=stall_timeout,
            next_ready=self.scheduler.next_ready_time, on_tick=self._tick, pace_margin=pace_margin,
            bitrate=bitrate, source_fit=self._source_fit)

    # -- contract API --------------------------------------------------------------------------

    def add_channel(self, key: int, policy: LinkPolicy, name: str | None = None, *,
                    whole: bool = False) -> None:
        """One channel per topic/service id; `name` (e.g. the topic) only makes logs clearer.
        `whole`: never fragmented (rmw_desert entries and beacons); other payloads longer than
        a packet are fragmented when the link has a fragment_id."""
        if key == self.fragment_id:
            raise ValueError(f"[{self.name}] channel {key} is the reserved fragment_id")
        self.scheduler.add_channel(key, policy, name=f"channel {key} ({name})" if name else None,
                                   whole=whole)

    def offer(self, key: int, payload: bytes, *, published: float | None = None) -> bool:
        """Queue an unframed payload; False (and a counted, logged drop) if it can never be sent.
        `published`: when its ROS publisher published it, on the link's clock; the channel's
        ttl runs from then (docs/seams.md section 4)."""
        ok = self.scheduler.offer(key, payload, published)
        if ok:
            self.connection.wake()
        return ok

    def queued(self, key: int) -> int:
        """Messages waiting on channel `key` (one being sent in fragments included)."""
        return self.scheduler.stats()[key]["queued"]

    def start(self) -> None:
        self.connection.start()

    def stop(self) -> None:
        self.connection.stop()

    @property
    def connected(self) -> bool:
        return self.connection.connected

    def stats(self) -> dict:
        """JSON-able counters: per channel, connection, fragments (None without fragment_id)."""
        conn = self.connection.stats()
        frag = None
        if self.reassembler is not None:
            frag = {**self.reassembler.stats.as_dict(), "pending": self.reassembler.pending,
                    "lost_by_id": dict(self.reassembler.lost_by_id),
                    "lost_unattributed": self.reassembler.lost_unattributed,
                    "buffered_bytes": self.reassembler.buffered_bytes,
                    "nested": self.counters["nested_fragments"]}
        return {
            "name": self.name,
            "connected": conn["connected"],
            "channels": self.scheduler.stats(),
            "connection": conn,
            "fragments": frag,
            "payloads_delivered": self.counters["payloads_delivered"],
            "security": self.guard.stats() if self.guard is not None else None,
        }

    # -- wiring --------------------------------------------------------------------------------

    def _source(self, now: float) -> bytes | None:
        picked = self.scheduler.next_payload(now)
        if picked is None:
            return None
        self._pulled_key = picked[0]
        return picked[1]

    def _source_fit(self, now: float, max_size: int) -> bytes | None:
        # The frame pulled last did not fit and is held: its channel must not overtake it.
        held = self._pulled_key if self.connection.outbox.pending else None
        picked = self.scheduler.next_payload(now, max_size, exclude=held)
        return None if picked is None else picked[1]

    def _on_frame(self, payload: bytes) -> None:
        if self.reassembler is not None and is_fragment(payload, self.fragment_id):
            whole = self.reassembler.feed(payload)
            if whole is None:
                return
            if is_fragment(whole, self.fragment_id):
                self.counters.inc("nested_fragments")    # never sent by uwgen: refuse to recurse
                return
            payload = whole
        if self.guard is not None:
            payload = self.guard.unprotect(payload)
            if payload is None:
                return                                   # counted by the guard
        self.counters.inc("payloads_delivered")
        if self._on_payload is not None:
            self._on_payload(payload)

    def _tick(self, now: float) -> None:
        if self.reassembler is not None:
            self.reassembler.expire(now)
