"""The emulator's sans-IO core: DESERT nodes and the acoustic channel as a discrete-event model.

No sockets and no clock: every input carries its time (`client_data(node, t, data)`,
`client_attached(node, t)`, ...), `advance(t)` runs the model up to `t` and returns the
packets delivered by then, and `next_event_time()` says when something happens next.
The socket shell (`uwgen.emulator.server`) drives it with the real clock; tests and the
PDR sweep drive it with explicit times, so timing, loss and collision statistics are
exact, deterministic (seeded) and fast.

What one node does (after DESERT's UW/APPLICATION in TCP mode, UW/CSMA_ALOHA or UW/TDMA,
and UW/PHYSICAL; docs/emulator.md, "What a node does", says each rule in full):
- bytes from its client are cut into packets of at most max_read_length bytes and queued
  (unbounded, as in DESERT); every `period` (a fixed grid from the node's start) one goes
  down to the MAC;
- CSMA-ALOHA: the only carrier sense is the PHY's lock (DESERT's Phy2MacStartRx); it waits
  while sending or locked, listens `listen_time` (+ jitter), sends when the listen ends
  unless locked by then (then it listens again after that reception);
  TDMA: as DESERT's UW/TDMA (uwgen.emulator.tdma): a packet starts anywhere in the node's
  ON window (slot - guard) and may end past it, at most max_packet_per_slot per window, and
  a full MAC queue (queue_size) drops the new packet, counted;
- a packet is on the air (bytes + header) * 8 / bitrate seconds and reaches every other node
  after distance / sound speed, taken when it is sent (nodes may move: uwgen.emulator.motion);
- a receiver locks onto the first packet it can acquire; one arriving while it sends or is
  locked is lost, and sending kills a reception (half duplex); the locked packet is lost
  ("collision") if the MEANPOWER interference of overlapping packets makes it draw BPSK bit
  errors; with an SNR model a packet under the acquisition threshold or with bit errors is
  lost ("snr"); then the fixed packet error rate applies ("per");
- a packet is for one node or, `dest: "*"`, every other (each its own copy); an intact one
  is written to the node's client, or dropped ("no_client") when none is connected.
"""
from __future__ import annotations

import heapq
import itertools
import logging
import math
import random
from collections import deque
from dataclasses import dataclass, field

from uwgen.emulator import tdma
from uwgen.emulator.motion import Geometry
from uwgen.emulator.physics import locked_outcome
from uwgen.emulator.scenario import BROADCAST, NodeSpec, Scenario
from uwgen.runtime.stats import Counters

log = logging.getLogger(__name__)

LOSS_CAUSES = ("per", "snr", "collision", "no_client")

# Counters that only grow; `counters()` adds the node's current state (queue_bytes,
# max_queue_bytes, client_connected).
NODE_COUNTERS = (
    "bytes_in",            # read from this node's client
    "packets_queued",      # packets cut from those bytes
    "packets_sent",        # transmissions started
    "bytes_sent",          # payload bytes of those
    "packets_delivered",   # packets written to this node's client
    "bytes_delivered",
    "dropped_restart",     # this node's packets queued or in flight at a restart
    "dropped_queue_full",  # TDMA: refused by a full MAC queue (queue_size_, the new one dropped)
    "clients",             # client connections served
    *(f"lost_{cause}" for cause in LOSS_CAUSES),   # packets addressed to this node and lost
)

# Event kinds, in the order they run when they share a time: a reception that ends at the
# instant another begins does not overlap it, and a node that stops sending at t can
# receive from t.
_RX_END, _TX_END, _RX_START, _TICK, _MAC, _LISTEN_END = range(6)

_IDLE, _WAITING, _LISTENING, _SENDING = "idle", "waiting", "listening", "sending"


@dataclass(frozen=True)
class Delivery:
    """Bytes that reached `node`'s client, and when (simulated seconds)."""

    node: str
    data: bytes
    time: float          # the packet's last bit arrived
    source: str
    queued_at: float     # when its bytes were read from the source's client
    sent_at: float       # when its transmission started
    offset: int = 0      # position of its first byte among all bytes the source's clients wrote
    uid: int = 0         # the packet's number (unique in one emulator)


@dataclass
class _Packet:
    uid: int
    source: str
    dest: str
    data: bytes
    queued_at: float
    offset: int = 0
    sent_at: float = 0.0


@dataclass
class _Arrival:
    packet: _Packet
    receiver: str
    start: float
    end: float
    power: float                 # mean received power, linear (1.0 without SNR model)
    snr_db: float                # faded SNR (inf without SNR model)
    interference: float = 0.0    # mean power of the packets that overlapped it (MEANPOWER)
    fail: str | None = None      # cause fixed at its start (not locked onto)


@dataclass
class _Node:
    name: str
    dest: str
    period: float
    max_read_length: int
    origin: float                               # tick grid: origin + k * period
    mac_origin: float                           # TDMA frames: from when DESERT started (no phase)
    app_queue: deque = field(default_factory=deque)
    mac_queue: deque = field(default_factory=deque)
    queue_bytes: int = 0                        # waiting inside the node (not yet on the air)
    max_queue_bytes: int = 0
    tick_pending: bool = False
    mac_state: str = _IDLE
    tx_end: float = -math.inf
    rx: list = field(default_factory=list)      # arrivals in progress
    locked: _Arrival | None = None              # the reception the PHY is synchronised on
    client: bool = False
    slot_frame: int = -(2 ** 62)                # TDMA: the ON window the node last sent in...
    slot_sent: int = 0                          # ...and how many packets it started there
    slot_frame_next: int = 0
    max_mac_queue: int = 0
    transits: deque = field(default_factory=lambda: deque(maxlen=50_000))   # its packets' delivered - queued
    counters: Counters = field(default_factory=lambda: Counters(NODE_COUNTERS))


class EmulatorCore:
    """N DESERT nodes on one acoustic channel, advanced by explicit times (see module doc)."""

    def __init__(self, scenario: Scenario, start: float = 0.0):
        self.scenario = scenario
        self.now = float(start)
        self.restarts = 0
        # One stream per kind of chance, each from the seed: how many packets a run
        # happens to send, or when a carrier is heard, cannot shift which numbers the
        # packet-error draws get, so one seed gives the same losses in real time too.
        seed = scenario.seed
        self._listen_rng = random.Random(f"{seed}/listen")
        self._fading_rng = random.Random(f"{seed}/fading")
        self._bit_error_rng = random.Random(f"{seed}/bit-errors")
        self._per_rng = random.Random(f"{seed}/per")
        self._events: list = []
        self._seq = itertools.count()
        self._uids = itertools.count(1)
        self._pending: list[Delivery] = []
        s = scenario
        self._nodes = {spec.name: self._fresh_node(spec, start) for spec in s.nodes}
        self._order = list(self._nodes)
        snr = s.snr
        # Where nodes are, and what a packet between two of them meets (motion.Geometry).
        self.geometry = Geometry(s, start)
        self._noise = 10 ** (self.geometry.noise_db / 10) if snr else 0.0

    # ------------------------------------------------------------------ inputs
    def client_attached(self, node: str, t: float) -> None:
        """A client connected to `node` (it receives what arrives from now on)."""
        self._run_until(t)
        n = self._node(node)
        n.client = True
        n.counters.inc("clients")

    def client_detached(self, node: str, t: float) -> None:
        self._run_until(t)
        self._node(node).client = False

    def set_position(self, node: str, t: float, position) -> None:
        """From `t` on, `node` is at `position` (x, y, z metres): a live pose overrides its
        waypoints and fixed position. Packets sent from then on use it."""
        self._run_until(t)
        self._node(node)
        self.geometry.set_position(node, position)

    def position(self, node: str, t: float | None = None) -> tuple[float, float, float]:
        """Where `node` is at `t` (default: now)."""
        self._node(node)
        return self.geometry.position(node, self.now if t is None else t)

    def client_data(self, node: str, t: float, data: bytes) -> int:
        """Bytes read from `node`'s client at `t`: cut and queued. Returns packets queued."""
        self._run_until(t)
        n = self._node(node)
        if not data:
            return 0
        base = n.counters["bytes_in"]
        n.counters.inc("bytes_in", len(data))
        count = 0
        for i in range(0, len(data), n.max_read_length):
            chunk = bytes(data[i:i + n.max_read_length])
            n.app_queue.append(_Packet(next(self._uids), n.name, n.dest, chunk, t, base + i))
            n.queue_bytes += len(chunk)
            count += 1
        n.counters.inc("packets_queued", count)
        n.max_queue_bytes = max(n.max_queue_bytes, n.queue_bytes)
        if not n.tick_pending:
            self._schedule_tick(n, t)
        return count

    def reset(self, t: float) -> None:
        """A DESERT restart at `t`: queues and packets in flight are lost, clients are gone,
        and every node's send ticks start again from `t`."""
        self._run_until(t)
        for n in self._nodes.values():
            n.counters.inc("dropped_restart", len(n.app_queue) + len(n.mac_queue))
        # Packets on their way: arriving, or still propagating (counted once each, a
        # broadcast too).
        in_flight = [arr for n in self._nodes.values() for arr in n.rx]
        in_flight += [args for _, _, _, kind, args in self._events if kind == _RX_START]
        for uid, source in {(a.packet.uid, a.packet.source) for a in in_flight
                            if a.packet.dest in (a.receiver, BROADCAST)}:
            self._nodes[source].counters.inc("dropped_restart")
        self._events.clear()
        for spec in self.scenario.nodes:
            old = self._nodes[spec.name]
            n = self._fresh_node(spec, t)
            n.counters, n.max_queue_bytes = old.counters, old.max_queue_bytes   # kept
            self._nodes[spec.name] = n
        self.restarts += 1

    # ------------------------------------------------------------------ time
    def advance(self, t: float) -> list[Delivery]:
        """Run every event up to and including `t`; return the deliveries since the last call."""
        self._run_until(t)
        out, self._pending = self._pending, []
        return out

    def next_event_time(self) -> float | None:
        return self._events[0][0] if self._events else None

    def run_until_idle(self, limit: float = math.inf) -> list[Delivery]:
        """Simulation helper: advance until nothing is left to happen (or `limit`)."""
        while self._events and self._events[0][0] <= limit:
            self._run_until(self._events[0][0])
        return self.advance(self.now)

    # ------------------------------------------------------------------ outputs
    def counters(self, node: str) -> dict[str, int]:
        n = self._node(node)
        ms = sorted(n.transits)
        pick = (lambda q: round(1000 * ms[min(len(ms) - 1, int(q * len(ms)))])) if ms else (lambda q: 0)
        return {**n.counters.as_dict(), "queue_bytes": n.queue_bytes,
                "max_queue_bytes": n.max_queue_bytes, "max_mac_queue": n.max_mac_queue,
                "client_connected": int(n.client), "transit_p50_ms": pick(0.5),
                "transit_p95_ms": pick(0.95), "transit_max_ms": pick(1.0)}

    def all_counters(self) -> dict[str, dict[str, int]]:
        return {name: self.counters(name) for name in self._order}

    # ------------------------------------------------------------------ engine
    def _fresh_node(self, spec: NodeSpec, start: float) -> _Node:
        """`spec`'s node as DESERT starts it at `start`: idle, empty queues, no client."""
        s = self.scenario
        return _Node(name=spec.name, dest=s.dest_of(spec.name), period=s.period_of(spec.name),
                     max_read_length=s.max_read_length_of(spec.name), origin=start + spec.phase,
                     mac_origin=start)

    def _node(self, name: str) -> _Node:
        try:
            return self._nodes[name]
        except KeyError:
            raise KeyError(f"no node named {name!r} (nodes: {', '.join(self._order)})") from None

    def _push(self, t: float, kind: int, args) -> None:
        heapq.heappush(self._events, (t, kind, next(self._seq), kind, args))

    def _run_until(self, t: float) -> None:
        if t < self.now - 1e-9:
            raise ValueError(f"time goes back: {t} < {self.now}")
        events = self._events
        while events and events[0][0] <= t:
            when, _, _, kind, args = heapq.heappop(events)
            self.now = max(self.now, when)
            if kind == _RX_END:
                self._rx_end(args, when)
            elif kind == _TX_END:
                self._tx_end(args, when)
            elif kind == _RX_START:
                self._rx_start(args, when)
            elif kind == _TICK:
                self._tick(args, when)
            elif kind == _MAC:
                args.mac_state = _IDLE
                self._mac_try(args, when)
            else:
                self._listen_end(args, when)
        self.now = max(self.now, t)

    # -- application layer: the period tick ------------------------------------------
    def _schedule_tick(self, n: _Node, after: float) -> None:
        # The first tick is one period after the node started, as DESERT's timer.
        k = max(1, math.floor((after - n.origin) / n.period) + 1)
        when = n.origin + k * n.period
        if when <= after + 1e-12:       # rounding put us on (or before) `after`
            when += n.period
        n.tick_pending = True
        self._push(when, _TICK, n)

    def _tick(self, n: _Node, t: float) -> None:
        n.tick_pending = False
        if not n.app_queue:
            return
        pkt = n.app_queue.popleft()
        if self.scenario.tdma is not None and tdma.queue_full(self.scenario.tdma, len(n.mac_queue)):
            n.queue_bytes -= len(pkt.data)          # DESERT's UW/TDMA drops the new packet
            n.counters.inc("dropped_queue_full")
        else:
            n.mac_queue.append(pkt)
            n.max_mac_queue = max(n.max_mac_queue, len(n.mac_queue))
        self._mac_try(n, t)
        if n.app_queue:
            self._schedule_tick(n, t)

    # -- MAC -------------------------------------------------------------------------
    def _mac_try(self, n: _Node, t: float) -> None:
        if n.mac_state != _IDLE or not n.mac_queue:
            return
        s = self.scenario
        if s.tdma is not None:
            start, n.slot_frame_next = tdma.next_start(
                s.tdma, s.tdma_slots(), s.slot_of(n.name), n.mac_origin, t, n.slot_frame, n.slot_sent)
            if start > t:
                n.mac_state = _WAITING
                self._push(start, _MAC, n)
            else:
                self._tx_start(n, t)
            return
        busy = self._busy_until(n, t)
        if busy > t:
            n.mac_state = _WAITING
            self._push(busy, _MAC, n)
            return
        n.mac_state = _LISTENING
        listen = s.listen_time
        if s.listen_jitter:
            listen += s.listen_jitter * self._listen_rng.random()
        self._push(t + listen, _LISTEN_END, n)

    def _listen_end(self, n: _Node, t: float) -> None:
        if n.locked is not None:
            # The listen ran out during a reception: DESERT listens again once it ends
            # (a reception that began and ended inside the listen changes nothing).
            n.mac_state = _IDLE
            self._mac_try(n, t)
            return
        self._tx_start(n, t)

    def _busy_until(self, n: _Node, t: float) -> float:
        """When the MAC may start listening: after its own transmission and after the
        reception its PHY is locked on. Packets the PHY did not acquire (they arrived while
        it was sending or locked, or too weak) are not carrier for DESERT's MAC."""
        until = max(t, n.tx_end)
        if n.locked is not None:
            until = max(until, n.locked.end)
        return until

    def _tx_start(self, n: _Node, t: float) -> None:
        s = self.scenario
        pkt = n.mac_queue.popleft()
        n.queue_bytes -= len(pkt.data)
        if s.tdma is not None:                   # one more packet in this ON window
            if n.slot_frame_next != n.slot_frame:
                n.slot_frame, n.slot_sent = n.slot_frame_next, 0
            n.slot_sent += 1
        pkt.sent_at = t
        duration = s.tx_time(len(pkt.data))
        n.mac_state = _SENDING
        n.tx_end = t + duration
        n.counters.inc("packets_sent")
        n.counters.inc("bytes_sent", len(pkt.data))
        if n.locked is not None:          # half duplex: sending kills the reception
            n.locked.fail = "collision"
            n.locked = None
        snr = s.snr
        for r in self._order:
            if r == n.name:
                continue
            delay, power, mean_snr = self.geometry.link(n.name, r, t)
            start = t + delay
            if snr is not None:
                faded = mean_snr + (self._fading_rng.gauss(0.0, snr.fading_db) if snr.fading_db else 0.0)
            else:
                faded = math.inf
            # The end is the sender's tx_end plus the delay: the same expression as the start
            # of a packet it sends right after, so back-to-back packets never overlap by a
            # rounding error.
            end = n.tx_end + delay
            arr = _Arrival(pkt, r, start, end, power, faded)
            self._push(start, _RX_START, arr)
        self._push(n.tx_end, _TX_END, n)
        if log.isEnabledFor(logging.DEBUG):
            log.debug("%.3f %s: sends packet %d (%d B) to %s", t, n.name, pkt.uid,
                      len(pkt.data), pkt.dest)

    def _tx_end(self, n: _Node, t: float) -> None:
        n.mac_state = _IDLE
        self._mac_try(n, t)

    # -- PHY: reception --------------------------------------------------------------
    def _rx_start(self, arr: _Arrival, t: float) -> None:
        r = self._nodes[arr.receiver]
        # MEANPOWER: each overlapping pair adds the other's power times the share of the
        # reception it overlaps (every pair meets here once, when the later one starts).
        for other in r.rx:
            overlap = min(other.end, arr.end) - t
            if overlap > 0:
                other.interference += arr.power * overlap / (other.end - other.start)
                arr.interference += other.power * overlap / (arr.end - arr.start)
        if r.mac_state == _SENDING:
            arr.fail = "collision"          # half duplex: deaf while sending
        elif r.locked is not None:
            arr.fail = "collision"          # busy with another packet
        elif arr.snr_db < self._threshold():
            arr.fail = "snr"                # too weak to acquire
        else:
            r.locked = arr
        r.rx.append(arr)
        self._push(arr.end, _RX_END, arr)

    def _rx_end(self, arr: _Arrival, t: float) -> None:
        r = self._nodes[arr.receiver]
        r.rx.remove(arr)
        if r.locked is arr:
            r.locked = None
            cause = self._decide(arr)
        else:
            cause = arr.fail
        pkt = arr.packet
        if pkt.dest != r.name and pkt.dest != BROADCAST:
            return                          # overheard: it only interfered
        if cause is None and self.scenario.per > 0 and self._per_rng.random() < self.scenario.per:
            cause = "per"
        if cause is None and not r.client:
            cause = "no_client"
        if cause is not None:
            r.counters.inc(f"lost_{cause}")
            if log.isEnabledFor(logging.DEBUG):
                log.debug("%.3f %s: packet %d from %s lost (%s)", t, r.name, pkt.uid,
                          pkt.source, cause)
            return
        r.counters.inc("packets_delivered")
        r.counters.inc("bytes_delivered", len(pkt.data))
        self._nodes[pkt.source].transits.append(t - pkt.queued_at)
        self._pending.append(Delivery(r.name, pkt.data, t, pkt.source, pkt.queued_at,
                                      pkt.sent_at, pkt.offset, pkt.uid))

    def _threshold(self) -> float:
        snr = self.scenario.snr
        return snr.threshold_db if snr is not None else -math.inf

    def _decide(self, arr: _Arrival) -> str | None:
        """Outcome of a packet the receiver stayed locked on to its end (physics.locked_outcome)."""
        return locked_outcome(self.scenario.snr, (len(arr.packet.data) + self.scenario.header_bytes) * 8,
                              arr.snr_db, arr.interference, self._noise, self._bit_error_rng)
