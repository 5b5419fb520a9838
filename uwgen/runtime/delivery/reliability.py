"""Reliable delivery wired into a wire format 2 link (docs/wire-format.md section 15).

`Reliability(...).hooks()` is reliability's `PacketHooks` (docs/seams.md section 5); the
bridge joins it with the seal's (`packets.join_hooks`) and passes it to `Link(hooks=)`. It
drives the pure engine `uwgen.runtime.delivery.reliable.ReliableLink`:

- sending: every packet's messages are told to the engine (`sent`), with the deadline of
  messages of reliable entries (publication + ttl); an A part acknowledging the peers'
  packets rides on packets that leave anyway (when a peer waits for an ack of a reliable
  message, or every `ack_interval` while there is news), and a packet with only the A part
  leaves when a peer has waited `ack_delay` for one; messages the peer lost (reliable
  entries) are sent again first (`resend`), until their deadline;
- receiving: every envelope's number feeds the engine (`received`) and its A part the
  sender's ledger (`acked`); each whole message's head is taken off (`admit`): a reliable
  message is delivered once (copies counted `duplicates`), a message with a max age is
  refused when older (`stale`, uwgen.runtime.delivery.staleness);
- T (the packet's time, `freshness.stamp` of the injected wall clock) goes on every packet
  carrying a message with a max age.

The per-entry ledger (`ledger()`, in the link's stats as `ledger`) is exact from packet
numbers: sent = delivered + lost_on_link + in_flight + unacknowledged, per channel key.
Everything is called on the link's thread except `stats()`; a lock keeps them apart.
"""
from __future__ import annotations

import logging
import threading
from collections import deque
from dataclasses import asdict

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import WALL_CLOCK, Clock
from uwgen.runtime.wire.framing import MAX_FRAME
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.wire.heads import HeadError, Heads
from uwgen.runtime.link.packets import PacketHooks, message_measure
from uwgen.runtime.delivery.acks import A_ROOM, AckPolicy
from uwgen.runtime.delivery.reliable import (RECEIVED_WINDOW, REPORT_KEY, ReliableLink, RttEstimator,
                                    Sent, unwrap)
from uwgen.runtime.delivery.staleness import Staleness
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link.reliability")

COUNTERS = ("stale", "clock_offset", "bad_heads", "bad_acks", "untimed", "restarts_seen",
            "duplicate_packets")
DEFAULT_DEADLINE = 120.0          # seconds: a reliable entry without a ttl
FORGET_AFTER = 2048               # packets: older ones cannot be named unambiguously (12 bits)
# T, and an A part of one report (acks.A_ROOM): the most the hooks add to a packet.
OVERHEAD = env.TIME_LEN + A_ROOM


def wire_id(key: int) -> int:
    """The wire id of a link channel key (an action's feedback channel is 256 + id)."""
    return key - 256 if key >= 256 else key


class Reliability:
    """One side's reliability on one link (see the module docstring)."""

    def __init__(self, sender: int, *, period: float, reliable: dict[int, float | None],
                 max_ages: dict[int, float], wall: Clock = WALL_CLOCK,
                 ack_delay: float | None = None, ack_interval: float | None = None,
                 name: str = "link", max_read_length: int = MAX_FRAME,
                 other_overhead: int = 0):
        self.sender, self.name, self.wall = sender, name, wall
        # what a packet may hold besides P, W and the messages: the frame's payload minus what
        # the other joined hooks (the seal) may add; the A part takes what is left (acks.A_ROOM
        # at least, kept free by `overhead`)
        self._part_room = min(max_read_length, MAX_FRAME) - FRAME_OVERHEAD - env.HEAD - other_overhead
        self._room = 0
        self.deadlines = {k: (DEFAULT_DEADLINE if t is None else t) for k, t in reliable.items()}
        self.max_ages = dict(max_ages)
        self.heads = Heads(numbered=frozenset(wire_id(k) for k in reliable),
                           aged=frozenset(max_ages))
        self.ack_delay = ack_delay if ack_delay is not None else max(1.0, 4 * period)
        self.ack_interval = ack_interval if ack_interval is not None else max(2.0, 8 * period)
        first = max(2.0, 8 * period)
        self.engine = ReliableLink(sender, RttEstimator(first, period, 60.0, period),
                                   ack_delay=self.ack_delay)
        self.staleness = Staleness()
        self.counters = Counters(COUNTERS)
        self.stale_by_id: dict[int, int] = {}
        self._lock = threading.Lock()
        self._deadline_of: dict[int, float] = {}      # channel key -> its message being sent
        self._timed = False                           # the packet being built needs T
        self._queue: deque[Sent] = deque()            # lost reliable messages to send again
        self._resending: dict[int, Sent] = {}         # id(payload) -> the copy picked now
        self.acks = AckPolicy(self.engine, ack_delay=self.ack_delay, ack_interval=self.ack_interval)
        self._epochs: dict[int, bytes] = {}
        self._restarts: dict[int, int] = {}
        self._rx: tuple[int, bytes, int | None] | None = None
        self._offset_told: set[int] = set()

    def hooks(self) -> PacketHooks:
        return PacketHooks(parts=self.parts, sent=self.sent, received=self.received,
                           overhead=OVERHEAD, next_overhead=self.next_overhead,
                           part_room=self.part_room, carrying=self.carrying, resend=self.resend,
                           ack_only=self.ack_only, next_time=self.next_time, stamp=self.stamp,
                           head_room=self.head_room, admit=self.admit, stats=self.stats)

    # -- sending ------------------------------------------------------------------------

    def next_overhead(self, now: float) -> int:
        """Room the next packet keeps for an A part: one report's (acks.A_ROOM) when one is
        due, else none (docs/seams.md section 9: nothing is reserved by constant). T is
        counted per message instead (`part_room`)."""
        with self._lock:
            return A_ROOM if self.acks.due(self._epochs, now) else 0

    def part_room(self, key: int) -> int:
        """Bytes a message of channel `key` brings into its packet's parts: T (3) for an
        entry with a max age, once a packet."""
        return env.TIME_LEN if wire_id(key) in self.max_ages else 0

    def head_room(self, key: int) -> int:
        return self.heads.room(wire_id(key))

    def stamp(self, key: int, payload: bytes, born: float, now: float) -> bytes:
        with self._lock:
            if key in self.deadlines:
                self._deadline_of[key] = born + self.deadlines[key]
            stamped, _ = self.heads.add(payload, now - born)
            return stamped

    def carrying(self, picked: list[tuple[int, bytes]], now: float) -> None:
        self._timed = any(wire_id(key) in self.max_ages for key, _ in picked)
        used = sum(message_measure(p) for _, p in picked) - (1 if picked else 0)
        self._room = self._part_room - used - (env.TIME_LEN if self._timed else 0)

    def parts(self, now: float) -> dict:
        with self._lock:
            out: dict = {}
            if self._timed:
                out["time"] = stamp(self.wall.now())
            ack = self.acks.a_part(self._epochs, now, self._room)
            if ack:
                out["ack"] = ack
            return out

    def sent(self, number: int, picked: list[tuple[int, bytes]], now: float) -> None:
        with self._lock:
            messages = []
            for key, payload in picked:
                again = self._resending.pop(id(payload), None)
                deadline = again.deadline if again is not None else self._deadline_of.get(key)
                messages.append(Sent(key, payload, deadline))
            self._resending.clear()
            messages += self.acks.carried()      # its reports: confirmed once it is acked
            self.engine.sent(number, messages, now)
            self.engine.forget(number - FORGET_AFTER)
            self._timed = False

    def resend(self, now: float, room: int) -> tuple[int, bytes] | None:
        with self._lock:
            self._queue.extend(self.engine.due(now))
            for m in list(self._queue):
                if m.deadline is not None and m.deadline <= now:
                    self._queue.remove(m)
                    self.engine.entry(m.key).expired += 1
                elif message_measure(m.ref) <= room:
                    self._queue.remove(m)
                    self._resending[id(m.ref)] = m
                    return m.key, m.ref
            return None

    def ack_only(self, now: float) -> bool:
        with self._lock:
            return self.acks.alone(now)

    def next_time(self, now: float) -> float | None:
        with self._lock:
            if self._queue:
                return now
            times = [t for t in [self.engine.next_timeout()] if t is not None]
            times += self.acks.next_times()
            return max(now, min(times)) if times else None

    # -- receiving ------------------------------------------------------------------------

    def received(self, envelope: env.Envelope, now: float) -> None:
        with self._lock:
            peer = envelope.sender
            epoch = self._epoch(envelope)
            eliciting = any(m.id in self.heads.numbered and m.kind == 0 for m in envelope.messages)
            if not self.engine.received(peer, epoch, envelope.number, now, eliciting):
                self.counters.inc("duplicate_packets")
            self.acks.heard(peer, bool(envelope.messages), now)
            if envelope.ack is not None:
                before = self.engine.bad_acks
                self.engine.acked(envelope.ack, now)
                self.acks.confirm()
                if self.engine.bad_acks > before:
                    log_count(log, logging.WARNING, self.counters.inc("bad_acks"),
                              "[%s] ignored an acknowledgement from sender %d that is malformed "
                              "or names packets never sent: %s", self.name, peer,
                              envelope.ack.hex(" "))
            self._rx = (peer, epoch, envelope.time)

    def _epoch(self, envelope: env.Envelope) -> bytes:
        """The sender's epoch: K's when the packet has one (the seal's); otherwise the last
        known, or a new one when its number fell behind the window (it restarted)."""
        peer = envelope.sender
        if envelope.sync is not None:
            self._epochs[peer] = envelope.sync.epoch
            return envelope.sync.epoch
        epoch = self._epochs.get(peer, b"")
        r = self.engine.receipts.get((peer, epoch))
        if r is not None and r.largest is not None and \
                unwrap(envelope.number, r.largest) < r.largest - RECEIVED_WINDOW:
            self._restarts[peer] = self._restarts.get(peer, 0) + 1
            self.counters.inc("restarts_seen")
            epoch = self._epochs[peer] = b"restart %d" % self._restarts[peer]
        return epoch

    def admit(self, payload: bytes, now: float) -> bytes | None:
        with self._lock:
            try:
                got = self.heads.take(payload)
            except HeadError as e:
                log_count(log, logging.WARNING, self.counters.inc("bad_heads"),
                          "[%s] dropped a message whose reliability head is malformed: %s",
                          self.name, e)
                return None
            ident = env.from_v1(got.payload).id if got.number is not None or got.age is not None else None
            peer, epoch, time24 = self._rx if self._rx is not None else (-1, b"", None)
            if got.number is not None and not self.engine.deliver_once(peer, epoch, ident, got.number):
                return None
            if got.age is not None and self._stale(ident, peer, time24, got.age):
                return None
            return got.payload

    def _stale(self, ident: int, peer: int, time24: int | None, age: float) -> bool:
        if time24 is None:
            self.counters.inc("untimed")
        verdict = self.staleness.judge(peer, time24, age, self.max_ages[ident], self.wall.now())
        if verdict.offset is not None:
            self.counters.inc("clock_offset")
            if peer not in self._offset_told:
                self._offset_told.add(peer)
                log.error("[%s] sender %d's clock is about %.1f s %s ours, more than the "
                          "%.0f s tolerance: commands' ages on the link cannot be judged, so "
                          "they are judged by the time they waited before sending only. Set both "
                          "clocks from GPS or NTP (counted clock_offset)", self.name, peer,
                          abs(verdict.offset), "behind" if verdict.offset > 0 else "ahead of",
                          self.staleness.tolerance)
        if verdict.stale:
            self.stale_by_id[ident] = self.stale_by_id.get(ident, 0) + 1
            log_count(log, logging.WARNING, self.counters.inc("stale"),
                      "[%s] refused a message of id %d from sender %d: %.1f s old, its max age "
                      "is %.1f s (counted stale)", self.name, ident, peer, verdict.age,
                      self.max_ages[ident])
        return verdict.stale

    # -- reporting ---------------------------------------------------------------------------

    def ledger(self) -> dict[int, dict[str, int]]:
        """Per channel key: sent = delivered + lost_on_link + in_flight + unacknowledged (copies),
        with resent and expired (reliable entries) and duplicates received."""
        with self._lock:
            flying = self.engine.in_flight()
            out = {k: {**asdict(e), "in_flight": flying.get(k, 0)}
                   for k, e in self.engine.ledger.items() if k != REPORT_KEY}
            for k, n in self.engine.duplicates.items():
                out.setdefault(k, {})["duplicates"] = n
            for k, n in self.stale_by_id.items():
                out.setdefault(k, {})["stale"] = n
            return out

    def stats(self) -> dict:
        ledger = self.ledger()
        with self._lock:
            rtt = self.engine.rtt
            return {"ledger": ledger,
                    "reliability": {**self.counters.as_dict(), "rto": rtt.rto, "srtt": rtt.srtt,
                                    "rtt_samples": rtt.samples,
                                    "spurious_resends": self.engine.spurious,
                                    "clock_offsets": dict(self.staleness.offsets)}}
