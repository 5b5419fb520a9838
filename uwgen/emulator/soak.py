"""A long run of the whole link stack on simulated time: the demo's traffic between two Links
through the emulator core, with packet loss, DESERT restarts and reconnects.

    soak = Soak(seed=1)
    soak.run(hours=24.0)
    soak.check()                       # raises AssertionError saying what does not add up
    soak.report()                      # dict of counters and figures

What runs is the real code of each side's `Link` (scheduler with the demo manifest's
policies, fragmenter and reassembler, the connection's pacer, outbox and frame decoder)
and the real `EmulatorCore` (calibrated CSMA-ALOHA, SNR model, `per` on top), all on one
`ManualClock`. The harness plays what the connection's thread does with a socket, at the
instants it would act: when the pacer allows a write it takes the outbox's batch (pulled
from the scheduler) and hands it to the emulated DESERT node; bytes the node delivers go
to the other side's decoder; after a silence the decoder is flushed; each turn the link's
housekeeping (fragment expiry) runs. A DESERT restart drops both clients: each side
abandons its cut frame and resets its decoder as on a disconnect, and reconnects after
DESERT is back plus its own backoff delay. (The socket calls themselves are tested
against the real emulator in tests/runtime and tests/e2e.)

The time loop jumps from event to event (traffic, restarts, the core's next event, the
pacer's next write when something is ready, decoder stalls), so a simulated day takes
minutes, not a day.

Messages are binary and full of the framing's own bytes: their channel, a 6-byte sequence
number, and filler of 0x99 0x99 LEN ... 0x55 look-alikes (wire-format section 2), the case
where a damaged stream could yield a false frame. The receiving side rebuilds each one from
its number and checks it exactly, in order and once, with O(1) memory per channel: no false
frame is allowed (packet-aligned writes keep every frame inside one packet).

Memory is the process's resident set (RSS, /proc/self/statm), sampled from the start of the
run, so warm-up counts and a short run measures as much as a long one. The ledger closes
per flow: sent = delivered + lost, with the link's own loss counts checked against it
(`link_ledger`: exact once the link reports it, wire-format.md section 15.7).
"""
from __future__ import annotations

import gc
import heapq
import itertools
import math
import os
import random
import resource
import time
from collections import Counter
from dataclasses import dataclass, field

from uwgen.emulator.core import EmulatorCore
from uwgen.emulator.physics import SnrModel
from uwgen.emulator.soak_checks import problems
from uwgen.emulator.scenario import NodeSpec, Scenario
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.link import Link
from uwgen.runtime.delivery.reliability import Reliability

FRAGMENT_ID = 250
SIDES = ("surface", "vehicle")
LINK = LinkConfig(max_read_length=64, period=0.2)


def _fit(conn) -> tuple:
    """The connection's `fit` callback when its outbox takes one (packet-aligned writes fill
    the room left in a write with a frame that fits), else nothing."""
    fit = getattr(conn, "_fit", None)
    return (fit,) if fit is not None else ()


@dataclass(frozen=True)
class Flow:
    """One stream of messages: `key` on `src`'s link, one message every `every` seconds."""

    name: str
    src: str
    key: int
    kind: int            # wire header kind: 0 topic, 2 request, 3 response
    every: float | None  # None: sent in answer to another flow (a service response)
    sizes: tuple[int, ...]
    policy: LinkPolicy

    def payload(self, seq: int) -> bytes:
        """Message `seq` of this flow: header, the number (6 bytes), filler to its size made
        of the framing's sync and end bytes (a different phase for each number)."""
        head = bytes([self.kind, self.key]) + seq.to_bytes(SEQ_BYTES, "big")
        size = max(len(head), self.sizes[seq % len(self.sizes)])
        n, start = size - len(head), seq % len(SYNC_HEAVY)
        return head + (SYNC_HEAVY * (n // len(SYNC_HEAVY) + 2))[start:start + n]

    @staticmethod
    def seq_of(payload: bytes) -> int | None:
        return int.from_bytes(payload[2:2 + SEQ_BYTES], "big") if len(payload) >= 2 + SEQ_BYTES else None


SEQ_BYTES = 6
# Filler: the frame sync (0x99 0x99), a plausible LEN, the end byte 0x55, in runs, so that any
# cut of a frame leaves bytes that look like the start or the end of another.
SYNC_HEAVY = bytes([0x99, 0x99, 0x05, 0x55, 0x99, 0x55, 0x55, 0x99, 0x99, 0x99, 0x01, 0x55, 0x00, 0xFF])


def rss_bytes() -> int:
    """This process's resident set size now (Linux); elsewhere its peak (getrusage)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def link_ledger(sender_stats: dict, key: int) -> dict | None:
    """The sending link's own count of what became of entry `key` ({"sent", "delivered",
    "lost_on_link", "in_flight", "unacknowledged", ...}: uwgen.runtime.delivery.reliability, wire
    format 2 links), or None when the link does not report one (wire format 1). Soak.check
    holds it exactly against what arrived."""
    ledger = sender_stats.get("ledger")
    if not isinstance(ledger, dict):
        return None
    entry = ledger.get(key, ledger.get(str(key)))
    return entry if isinstance(entry, dict) and "lost_on_link" in entry else None


# The demo's traffic (uwgen/demo: operator and vehicle) with the demo manifest's policies
# (msg_samples/uwgen.yaml); sizes close to the CBOR encodings of those messages, log lines
# from short to longer than a frame (fragmented), service calls every 30 s.
DEMO_FLOWS = (
    Flow("/turtle1/cmd_vel", "surface", 4, 0, 0.1, (22,),
         LinkPolicy(rate=5, queue="latest", ttl=1.0, priority=10)),
    Flow("/turtle1/pose", "vehicle", 5, 0, 0.1, (26,),
         LinkPolicy(rate=2, queue="latest", ttl=2.0, priority=5)),
    Flow("/vehicle/battery", "vehicle", 6, 0, 1.0, (48,),
         LinkPolicy(rate=0.2, queue="latest", ttl=10.0, priority=1)),
    Flow("/vehicle/log", "vehicle", 7, 0, 15.0, (40, 120, 300, 700),
         LinkPolicy(queue="fifo", depth=8, ttl=60.0, priority=0)),
    Flow("/vehicle/set_pen request", "surface", 21, 2, 30.0, (18,),
         LinkPolicy(queue="fifo", depth=8, ttl=10.0, priority=0)),
    Flow("/vehicle/set_pen response", "vehicle", 21, 3, None, (8,),
         LinkPolicy(queue="fifo", depth=8, ttl=10.0, priority=0)),
)


@dataclass
class _Side:
    name: str
    link: Link
    connected: bool = True
    reconnect_at: float = math.inf
    last_rx: float = 0.0


@dataclass
class _Received:
    last: int = -1       # highest sequence number delivered
    count: int = 0       # delivered intact, in order, once
    repeated: int = 0    # a number at or below the last one: twice, or out of order
    corrupt: int = 0     # in order, but the content is not what was sent (a false frame)
    corrupt_sizes: Counter = field(default_factory=Counter)   # sent size -> false frames
    last_at: float = 0.0


@dataclass
class Soak:
    seed: int = 1
    per: float = 0.05                  # packet error rate on top of collisions (the demo's)
    distance: float = 300.0
    restart_every: float = 3600.0      # mean seconds between DESERT restarts
    down_time: float = 5.0             # seconds DESERT stays down
    flows: tuple = DEMO_FLOWS
    clock: ManualClock = field(default_factory=ManualClock)
    wire_format: int = 1               # 2: envelopes, acks and the links' own ledger (wire-format 15.7)

    def __post_init__(self) -> None:
        self.rng = random.Random(f"{self.seed}/soak")
        scen = Scenario(nodes=[NodeSpec("surface", dest="vehicle"),
                               NodeSpec("vehicle", position=(self.distance, 0.0, 0.0),
                                        dest="surface")],
                        period=LINK.period, max_read_length=LINK.max_read_length,
                        bitrate=4800.0, per=self.per, seed=self.seed, snr=SnrModel())
        self.core = EmulatorCore(scen)
        self.sides = {}
        for i, name in enumerate(SIDES):
            v2 = {}
            if self.wire_format == 2:
                hooks = Reliability(i + 1, period=LINK.period, reliable={}, max_ages={},
                                    max_read_length=LINK.max_read_length,
                                    name=name).hooks()
                v2 = {"wire_format": 2, "sender_id": i + 1, "hooks": hooks}
            link = Link(config=LINK, clock=self.clock, name=name, fragment_id=FRAGMENT_ID,
                        rng=random.Random(f"{self.seed}/{name}"),
                        on_payload=lambda p, name=name: self._received(name, p), **v2)
            self.sides[name] = _Side(name, link)
            self.core.client_attached(name, 0.0)
        self.by_key = {}
        for f in self.flows:
            self.sides[f.src].link.add_channel(f.key, f.policy, name=f.name)
            self.by_key[f.src, f.kind, f.key] = f
        self.responder = {(f.key, f.src): f for f in self.flows if f.every is None}
        self.next_seq = {f.name: 0 for f in self.flows}
        self.received = {f.name: _Received() for f in self.flows}
        self.unknown = 0
        self.restarts = 0
        self.reconnects = 0
        self._timers: list = []
        self._order = itertools.count()
        for f in self.flows:
            if f.every is not None:
                self._at(self.rng.uniform(0, f.every), ("send", f))
        self._at(self.rng.expovariate(1.0 / self.restart_every), ("restart", None))
        self.memory: list[tuple[float, int]] = []     # (simulated hours, RSS bytes)
        self.wall = 0.0

    # -- traffic and events ----------------------------------------------------------------
    def _at(self, t: float, what) -> None:
        heapq.heappush(self._timers, (t, next(self._order), what))

    def _send(self, flow: Flow, seq: int) -> None:
        self.sides[flow.src].link.offer(flow.key, flow.payload(seq))

    def _received(self, side: str, payload: bytes) -> None:
        flow = self.by_key.get((self._other(side), payload[0], payload[1]))
        if flow is None:
            self.unknown += 1
            return
        rec = self.received[flow.name]
        seq = flow.seq_of(payload)
        if seq is None or payload != flow.payload(seq):
            # A frame whose tail was lost with a packet, taken with the bytes after it up to
            # a 0x55 that happened to sit LEN bytes on (wire-format section 2: no checksum).
            rec.corrupt += 1
            rec.corrupt_sizes[len(payload)] += 1
            return
        if seq <= rec.last:
            rec.repeated += 1
            return
        rec.last = seq
        rec.count, rec.last_at = rec.count + 1, self.clock.now()
        answer = self.responder.get((flow.key, side))
        if answer is not None and flow.kind == 2:
            self._send(answer, seq)

    @staticmethod
    def _other(side: str) -> str:
        return "vehicle" if side == "surface" else "surface"

    def _restart(self, t: float) -> None:
        self.core.reset(t)
        self.restarts += 1
        for s in self.sides.values():
            if s.connected:
                conn = s.link.connection
                conn.outbox.abandon()        # as on a disconnect: the cut frame is gone
                conn.decoder.reset()
                s.connected = False
            s.reconnect_at = t + self.down_time + s.link.connection.backoff.next_delay()
        self._at(t + self.rng.expovariate(1.0 / self.restart_every), ("restart", None))

    # -- the loop --------------------------------------------------------------------------
    def run(self, hours: float, memory_every: float | None = None) -> None:
        """Play `hours` more simulated hours. With memory_every (hours), record the process's
        RSS (after a collection) at the start and at that interval."""
        until = self.clock.now() + hours * 3600.0
        next_mem = self.clock.now() if memory_every else math.inf
        wall0 = time.perf_counter()
        t = self.clock.now()
        while t <= until:
            self.clock.set(t)
            self._turn(t)
            if t >= next_mem:
                gc.collect()
                self.memory.append((t / 3600.0, rss_bytes()))
                next_mem = t + memory_every * 3600.0
            t = max(self._next_time(t), t + 1e-6)
        self.wall += time.perf_counter() - wall0

    def _turn(self, t: float) -> None:
        while self._timers and self._timers[0][0] <= t:
            _, _, (what, flow) = heapq.heappop(self._timers)
            if what == "send":
                self._send(flow, self.next_seq[flow.name])
                self.next_seq[flow.name] += 1
                self._at(t + flow.every, ("send", flow))
            else:
                self._restart(t)
        for s in self.sides.values():
            if not s.connected and t >= s.reconnect_at:
                s.connected, s.reconnect_at, s.last_rx = True, math.inf, t
                self.core.client_attached(s.name, t)
                s.link.connection.backoff.reset()
                self.reconnects += 1
        for s in self.sides.values():                 # what each connection thread writes
            if s.connected:
                conn = s.link.connection
                batch = conn.outbox.take(t, conn._pull, *_fit(conn))
                if batch:
                    self.core.client_data(s.name, t, batch)
                    conn.outbox.sent(t)
        for d in self.core.advance(t):                # what each connection thread reads
            s = self.sides[d.node]
            s.last_rx = t
            conn = s.link.connection
            conn._deliver(conn.decoder.feed(d.data))
        for s in self.sides.values():
            conn = s.link.connection
            if conn.decoder.buffered and t - s.last_rx >= conn.stall_timeout:
                conn._deliver(conn.decoder.flush())
            s.link._tick(t)

    def _next_time(self, t: float) -> float:
        times = [self._timers[0][0]] if self._timers else []
        core_next = self.core.next_event_time()
        if core_next is not None:
            times.append(core_next)
        for s in self.sides.values():
            conn = s.link.connection
            if not s.connected:
                times.append(s.reconnect_at)
                continue
            write_at = conn.pacer.next_write_at
            if conn.outbox.pending:
                times.append(write_at)
            else:
                ready = conn._next_ready(t) if conn._next_ready is not None else None
                if ready is not None:
                    times.append(max(ready, write_at))
            if conn.decoder.buffered:
                times.append(s.last_rx + conn.stall_timeout)
            if s.link.reassembler is not None and s.link.reassembler.pending:
                times.append(t + 1.0)                 # fragment expiry is checked each second
        return min(times)

    # -- results ---------------------------------------------------------------------------
    def drain(self, seconds: float = 120.0) -> None:
        """Stop offering and let everything in flight arrive or expire."""
        self._timers = [x for x in self._timers if x[2][0] != "send"]
        heapq.heapify(self._timers)
        self.run(seconds / 3600.0)

    def report(self) -> dict:
        hours = self.clock.now() / 3600.0
        return {
            "simulated_hours": hours,
            "wall_seconds": self.wall,
            "simulated_hours_per_wall_second": hours / self.wall if self.wall else float("nan"),
            "restarts": self.restarts,
            "reconnects": self.reconnects,
            "flows": {f.name: {"offered": self.next_seq[f.name] if f.every else None,
                               "delivered": self.received[f.name].count,
                               "repeated": self.received[f.name].repeated,
                               "corrupt": self.received[f.name].corrupt} for f in self.flows},
            "links": {name: s.link.stats() for name, s in self.sides.items()},
            "emulator": self.core.all_counters(),
            "memory": self.memory,
        }

    def ledger(self) -> dict[str, dict]:
        """Per flow: `sent` (the sending link's scheduler), `delivered` (intact, in order, once,
        checked here), `lost` = sent - delivered, `lost_seen` (fragmented messages the
        receiving link gave up: the part of the loss it saw) and `link` (the sending link's
        own ledger, `link_ledger`; None until it reports one)."""
        out = {}
        for f in self.flows:
            sender, receiver = self.sides[f.src].link, self.sides[self._other(f.src)].link
            sent = sender.scheduler.stats()[f.key]["sent"]
            delivered = self.received[f.name].count
            lost_by_id = (receiver.stats().get("fragments") or {}).get("lost_by_id") or {}
            seen = int(lost_by_id.get(f.key, lost_by_id.get(str(f.key), 0)))
            out[f.name] = {"sent": sent, "delivered": delivered, "lost": sent - delivered,
                           "lost_seen": seen, "link": link_ledger(sender.stats(), f.key)}
        return out

    def corrupt(self) -> int:
        return sum(r.corrupt for r in self.received.values())

    def corrupt_sizes(self) -> Counter:
        """How many messages of each sent size were delivered as false frames."""
        total: Counter = Counter()
        for r in self.received.values():
            total.update(r.corrupt_sizes)
        return total

    def check(self, drained: bool = False, corrupt_allowed: int = 0) -> None:
        """Everything adds up (raises AssertionError saying what does not): nothing delivered
        twice or out of order, at most `corrupt_allowed` false frames, every channel's
        offered = sent + queued + dropped, every byte written reached DESERT, and (drained)
        every packet DESERT took was delivered, lost or dropped by a restart."""
        found = problems(self, drained, corrupt_allowed)
        if found:
            raise AssertionError("; ".join(found))
