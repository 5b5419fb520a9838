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

Envelope links (`wire_format=2` here, links of profiles native and packed; they speak the
envelope's wire format, `envelope.VERSION`, which `stats()` reports): each write is one frame
holding one envelope of several messages (uwgen.runtime.link.packets, envelope; wire format section
14); profile-`packed` payloads (ids in `packed_ids`) travel without their byte string's head.
`hooks` (hooks.PacketHooks) are the seams of reliability and the per-packet seal. Wire format 1
(the default, and what rmw_desert-profile links use) writes one frame per payload.

Observers (`link.observers`): callables told of every packet written and read, with what became
of it (uwgen.runtime.link.watch; a bridge recorder is one).

Security: with a `guard` (uwgen.security.guard.LinkGuard) a whole payload is protected when it
leaves its queue, before it is fragmented, and every whole payload received (after reassembly)
goes through `guard.unprotect`; only what it passes reaches `on_payload`.
"""
from __future__ import annotations

import logging
import random
from collections.abc import Callable
from typing import Any

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.link.connection import Backoff, DesertConnection
from uwgen.runtime.wire.envelope import VERSION as ENVELOPE_VERSION
from uwgen.runtime.wire.envelope import EnvelopeError, add_packed_head, from_v1, strip_packed_head
from uwgen.runtime.wire.fragment import MAX_COUNT, Fragmenter, fragment_payload_for, is_fragment
from uwgen.runtime.wire.reassembly import Reassembler
from uwgen.runtime.wire.framing import LONG, MAX_FRAME, MAX_PAYLOAD, SHORT
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD
from uwgen.runtime.link.mac_base import Mac
from uwgen.runtime.link.hooks import PacketHooks, join_hooks
from uwgen.runtime.link.packets import (PACKET_COUNTERS, Packer, Unpacker, envelope_check, envelope_room,
                                        message_measure)
from uwgen.runtime.link.pacing import DEFAULT_MARGIN
from uwgen.runtime.link.probation import reconnect_cap
from uwgen.runtime.link.scheduler import LinkScheduler
from uwgen.runtime.link.watch import PacketWatch
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link")

LINK_COUNTERS = ("payloads_delivered", "nested_fragments", "not_packed")
WIRE_FORMATS = (1, 2)


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
                 guard: Any = None,
                 wire_format: int = 1,
                 sender_id: int = 0,
                 packed_ids: frozenset[int] | set[int] = frozenset(),
                 hooks: PacketHooks | None = None,
                 mac: Mac | None = None):
        if wire_format not in WIRE_FORMATS:
            raise ValueError(f"[{name}] wire format must be one of {WIRE_FORMATS}, got {wire_format}")
        self.config = config or LinkConfig()
        self.wire_format = wire_format
        self.packed_ids = frozenset(packed_ids) if wire_format == 2 else frozenset()
        self.mac = mac or Mac()
        own_hooks = hooks or PacketHooks()
        mac_hooks = self.mac.hooks() if wire_format == 2 else None
        self.hooks = join_hooks(own_hooks, mac_hooks) if mac_hooks is not None else own_hooks
        self.mac.backlog = lambda now: self._backlog(now, own_hooks)
        self.name = name
        self.clock = clock
        self.fragment_id = fragment_id
        self._on_payload = on_payload
        self.guard = guard
        self.counters = Counters(LINK_COUNTERS)
        self.packet_counters = Counters(PACKET_COUNTERS)
        v2 = wire_format == 2
        self._pulled_key: int | None = None       # channel of the payload pulled last
        self.watch = w = PacketWatch(name, clock, lambda: self.counters["payloads_delivered"],
                                     self.packet_counters)
        self.observers = self.watch.observers     # see module docstring
        rng = rng or random.Random()

        self.fragmenter: Fragmenter | None = None
        self.reassembler: Reassembler | None = None
        if fragment_id is not None:
            # A fragment frame fits one DESERT packet, so a lost packet costs whole fragments only.
            # Wire format 2: fragments are compact fragment messages (H 0x61, fragment.py), each
            # fitting an envelope's room with its length byte (packets.message_measure).
            room = (envelope_room(self.config.max_read_length, self.hooks.overhead) - 1 if v2
                    else fragment_payload_for(self.config.max_read_length))
            self.fragmenter = Fragmenter(fragment_id, rng=rng, max_fragments=max_fragments,
                                         max_payload=min(MAX_PAYLOAD, room), compact=v2)
            # Fragments of one message may be spread out by higher-priority traffic: be patient;
            # memory stays bounded by max_partial_* whatever the timeout.
            timeout = fragment_timeout if fragment_timeout is not None else max(30.0, 60 * self.config.period)
            self.reassembler = Reassembler(fragment_id, clock, timeout=timeout,
                                           max_transfers=max_partial_transfers,
                                           max_bytes=max_partial_bytes, name=name)
        self.scheduler = LinkScheduler(
            clock, name=name,
            splitter=self.fragmenter.split if self.fragmenter else None,
            max_message=(self.fragmenter.max_message_size if self.fragmenter
                         else envelope_room(MAX_FRAME, self.hooks.overhead) - 1 if v2 else MAX_PAYLOAD),
            fec_over=(self.whole_payload() if v2 else self.fragmenter.max_payload)
            if self.fragmenter else MAX_PAYLOAD,
            max_message_for=self.fragmenter.max_message_for if self.fragmenter else None,
            protect=guard.protect if guard is not None else None,
            overhead=_overhead_for(guard, self.hooks) if v2 else (guard.overhead if guard is not None else None),
            measure=message_measure if v2 else len,
            stamp=self.hooks.stamp if v2 else None, burst=self.mac.burst)
        self.packer: Packer | None = None
        self.unpacker: Unpacker | None = None
        if v2:
            self.packer = Packer(self.scheduler, sender=sender_id,
                                 max_read_length=self.config.max_read_length, hooks=self.hooks,
                                 counters=self.packet_counters, name=name)
            self.unpacker = Unpacker(self.hooks, counters=self.packet_counters, name=name)
        self.connection = DesertConnection(
            host, port, self.config, clock=clock, one_frame=v2,
            framing=SHORT if v2 else LONG, check=envelope_check if v2 else None,
            source=w.tx(self.packer.next_packet if v2 else self._source),
            on_frame=w.rx(self._on_packet if v2 else self._on_frame, envelopes=v2),
            name=name, backoff=backoff or Backoff(maximum=reconnect_cap(self.config.period), rng=rng),
            stall_timeout=stall_timeout,
            next_ready=self._next_ready if v2 else self.scheduler.next_ready_time,
            on_tick=self._tick, pace_margin=pace_margin,
            bitrate=bitrate, source_fit=None if v2 else w.tx(self._source_fit), mac=self.mac)

    # -- contract API --------------------------------------------------------------------------

    def add_channel(self, key: int, policy: LinkPolicy, name: str | None = None, *,
                    whole: bool = False) -> None:
        """One channel per topic/service id (`name`, e.g. the topic, for logs). `whole`: never
        fragmented (rmw_desert entries, beacons); longer payloads are, given a fragment_id."""
        if key == self.fragment_id:
            raise ValueError(f"[{self.name}] channel {key} is the reserved fragment_id")
        self.scheduler.add_channel(key, policy, name=f"channel {key} ({name})" if name else None,
                                   whole=whole)

    def offer(self, key: int, payload: bytes, *, published: float | None = None) -> bool:
        """Queue an unframed payload; False (and a counted, logged drop) if it can never be sent.
        `published`: when its ROS publisher published it, on the link's clock; the channel's
        ttl runs from then (docs/seams.md section 4)."""
        if self.packed_ids and payload and payload[0] < 24 and _wire_id(payload) in self.packed_ids:
            try:
                payload = strip_packed_head(payload)
            except EnvelopeError as e:
                log_count(log, logging.ERROR, self.counters.inc("not_packed"),
                          "[%s] channel %d: refused a payload of a packed id that is not packed: %s",
                          self.name, key, e)
                return False
        ok = self.scheduler.offer(key, payload, published)
        if ok:
            self.mac.offered(self.clock.now(), payload)
            self.connection.wake()
        return ok

    def whole_payload(self, key: int | None = None) -> int:
        """The longest payload of channel `key` that leaves whole in one packet, protection
        included: what a sender that splits its own data (schema announcements) aims for.
        Wire format 2: a message of that payload fills an envelope's room (its message cost is
        at most its payload length, packets.message_measure); 1: a frame of max_read_length."""
        room = (envelope_room(self.config.max_read_length, self.hooks.overhead)
                if self.wire_format == 2 else self.config.max_read_length - FRAME_OVERHEAD)
        guard = self.guard.overhead(key) if self.guard is not None and key is not None else 0
        return max(1, min(MAX_PAYLOAD, room - guard))

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
            "wire_format": ENVELOPE_VERSION if self.wire_format == 2 else 1,   # what it speaks
            "packets": self.packet_counters.as_dict() if self.wire_format == 2 else None,
            "security": self.guard.stats() if self.guard is not None else None,
            "mac": self.mac.stats(),
            **(self.hooks.stats() if self.wire_format == 2 and self.hooks.stats is not None else {}),
        }

    # -- wiring --------------------------------------------------------------------------------

    def _next_ready(self, now: float) -> float | None:
        """When the packer will next have something: a queued message, a cut message's tail
        (`Packer.tail_at`), or what the hooks want (an ack that must go alone, a re-send)."""
        times = [t for t in (self.scheduler.next_ready_time(now), self.packer.tail_at(now),
                             self.hooks.next_time(now) if self.hooks.next_time else None)
                 if t is not None]
        return min(times) if times else None

    def _backlog(self, now: float, hooks: PacketHooks) -> bool:
        """Whether another packet wants to leave by the time the pacer allows the next write
        (the MAC keeps the turn for it: a stream offered at the link's pace fills the turn)."""
        pacer = self.connection.pacer
        horizon = now + pacer.period * (1.0 + pacer.margin)
        times = [self.scheduler.next_ready_time(now), self.packer and self.packer.tail_at(now),
                 hooks.next_time(now) if hooks.next_time is not None else None]
        return any(t is not None and t <= horizon for t in times)

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

    def _on_packet(self, data: bytes) -> None:
        for payload in self.unpacker.feed(data, self.clock.now()):
            self._on_frame(payload)

    def _on_frame(self, payload: bytes) -> None:
        by: dict = {}                   # reassembled: {"transfer": t} (61 t index count ...)
        if self.reassembler is not None and is_fragment(payload, self.fragment_id,
                                                         compact=self.wire_format == 2):
            self.watch.fragment = True
            whole = self.reassembler.feed(payload)
            if whole is None:
                return
            if is_fragment(whole, self.fragment_id, compact=self.wire_format == 2):
                self.counters.inc("nested_fragments")    # never sent by uwgen: refuse to recurse
                self.watch.drop = "nested_fragment"
                return
            payload, by = whole, ({"transfer": payload[1]} if self.wire_format == 2 else {})
        if self.guard is not None:
            payload = self.guard.unprotect(payload)
            if payload is None:
                self.watch.drop = "security"
                return                                   # counted by the guard
        if self.wire_format == 2 and self.hooks.admit is not None:
            payload = self.hooks.admit(payload, self.clock.now(), **by)
            if payload is None:
                self.watch.drop = "not_admitted"
                return                                   # a copy, or stale: counted by the hook
        if self.packed_ids and _wire_id(payload) in self.packed_ids:
            try:
                payload = add_packed_head(payload)
            except EnvelopeError as e:
                log_count(log, logging.WARNING, self.counters.inc("not_packed"),
                          "[%s] dropped a received payload of a packed id without its fields: %s",
                          self.name, e)
                self.watch.drop = "not_packed"
                return
        self.counters.inc("payloads_delivered")
        if self._on_payload is not None:
            self._on_payload(payload)

    def _tick(self, now: float) -> None:
        if self.reassembler is not None:
            self.reassembler.expire(now)


def _overhead_for(guard: Any, hooks: PacketHooks) -> Callable[[int], int] | None:
    """What protection and the reliability head (wire format 2 hooks) add to a message."""
    protect = guard.overhead if guard is not None else None
    head = hooks.head_room
    if protect is None and head is None:
        return None
    return lambda key: (protect(key) if protect else 0) + (head(key) if head else 0)


def _wire_id(payload: bytes) -> int | None:
    """The id of a wire format 1 payload (None when it has none)."""
    try:
        return from_v1(payload).id
    except EnvelopeError:
        return None
