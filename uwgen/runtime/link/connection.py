"""The TCP client for one DESERT node's application socket (wire format section 1).

DESERT starts listening only when its scenario starts, serves one client at a time and may be
restarted, so the client connects, and reconnects with bounded exponential backoff (with jitter,
capped at one period or 1 s: DESERT drops what arrives for a node with no client) whenever the port
is not listening or the connection drops, without crashing and without SIGPIPE (writes use
MSG_NOSIGNAL and every socket error is a disconnect, not an exception out of the thread). A fresh
connection is reported and counted as connected, and written to, only once it has proved itself
(uwgen.runtime.link.probation); a proven one that never receives anything draws one warning.

Writes wait for the link's MAC too (uwgen.runtime.link.mac: a turn, a slot's share), and are
paced (uwgen.runtime.link.pacing): one write of at most `max_read_length` bytes per `period`,
filled by *pulling* payloads from `source` only when a write is allowed, so what waits, waits in the
scheduler's queues where policy can act, and DESERT's unbounded queue holds about one period of data.
A frame cut by a disconnect is abandoned and counted (never re-sent: the remote's decoder resyncs,
and re-sending could deliver it twice). Received bytes go through a FrameDecoder; complete payloads
go to `on_frame`, on the connection's thread.

The thread makes every decision with the injected clock; it waits with real timeouts (at most
HOUSEKEEPING seconds), so a ManualClock moved by a test is noticed within that time.
"""
from __future__ import annotations

import logging
import random
import select
import socket
import threading
from collections.abc import Callable

from uwgen.manifest.model import LinkConfig
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.wire.framing import LONG, FrameError, Framing
from uwgen.runtime.link.mac_base import Mac
from uwgen.runtime.link.pacing import DEFAULT_MARGIN, MIN_FRAME, Outbox, Pacer
from uwgen.runtime.link.probation import Event, Probation, reconnect_cap
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link")

HOUSEKEEPING = 0.25       # longest wait between two looks at the clock, the stop flag and timers
LOUD_RETRIES = 3          # connection failures logged one by one before going quiet
RECV_SIZE = 65536


class Backoff:
    """Bounded exponential backoff with jitter: initial * factor**n, capped at maximum.

    Each delay is scaled down by up to `jitter` (a random fraction from `rng`), so that several
    clients do not retry in lockstep; a seeded rng makes the sequence repeatable.
    """

    def __init__(self, initial: float = 0.1, maximum: float = 5.0, factor: float = 2.0,
                 jitter: float = 0.5, rng: random.Random | None = None):
        if not 0 < initial <= maximum or factor < 1 or not 0 <= jitter < 1:
            raise ValueError("Backoff needs 0 < initial <= maximum, factor >= 1, 0 <= jitter < 1")
        self.initial, self.maximum, self.factor, self.jitter = initial, maximum, factor, jitter
        self.rng = rng or random.Random()
        self.attempts = 0

    def next_delay(self) -> float:
        base = min(self.maximum, self.initial * self.factor ** min(self.attempts, 64))
        self.attempts += 1
        return base * (1.0 - self.jitter * self.rng.random())

    def reset(self) -> None:
        self.attempts = 0


CONNECTION_COUNTERS = (
    "connects", "reconnects", "connect_failures", "disconnects",
    "unproven",           # connections accepted and closed before they proved themselves
    "unserved_warnings",  # proven connections on which nothing ever arrived (one warning each)
    "frames_received", "bytes_received",
    "unframeable",        # payloads the source gave that cannot be framed (dropped)
    "callback_errors",    # on_frame raised (the frame is lost; the link goes on)
    "late_packets",       # built for a turn that was over when they were ready (not written)
)


class _Closed(OSError):
    pass


class DesertConnection:
    """One DESERT node's socket: connect/reconnect, paced writes pulled from `source`, decoded reads.

    `source(now)` returns the next payload to send (at most 255 bytes) or None; it is called only
    when a write may happen. `next_ready(now)` (optional) says when source will next have something,
    so the thread sleeps until then; without it the thread relies on `wake()` and polling.
    `on_tick(now)` (optional) is called on every loop turn (e.g. to expire partial fragments).
    """

    def __init__(self, host: str, port: int, config: LinkConfig, *,
                 source: Callable[[float], bytes | None],
                 on_frame: Callable[[bytes], None],
                 clock: Clock = SYSTEM_CLOCK, name: str = "desert",
                 backoff: Backoff | None = None,
                 stall_timeout: float | None = None,
                 next_ready: Callable[[float], float | None] | None = None,
                 on_tick: Callable[[float], None] | None = None,
                 connect_timeout: float = 2.0, write_timeout: float = 5.0,
                 stable_after: float = 1.0, pace_margin: float = DEFAULT_MARGIN,
                 bitrate: float | None = None, probation: float = 0.3,
                 unserved_after: float | None = None,
                 source_fit: Callable[[float, int], bytes | None] | None = None,
                 one_frame: bool = False, mac: Mac | None = None, framing: Framing = LONG,
                 check: Callable[[bytes], bool] | None = None):
        self.host, self.port, self.config, self.name = host, port, config, name
        self.clock = clock
        self._source, self._on_frame = source, on_frame
        self._source_fit = source_fit     # (now, max payload size) -> payload that fits, or None
        self._next_ready, self._on_tick = next_ready, on_tick
        self.backoff = backoff or Backoff(maximum=reconnect_cap(config.period))
        self.proof = Probation(probation, unserved_after if unserved_after is not None
                               else max(30.0, 50 * config.period))
        # A frame's chunks arrive about one period apart; far longer silence means its tail was lost.
        self.stall_timeout = stall_timeout if stall_timeout is not None else 4 * config.period + 1.0
        self.connect_timeout, self.write_timeout, self.stable_after = connect_timeout, write_timeout, stable_after

        self.pacer = Pacer.for_link(config, pace_margin, bitrate)
        self.mac = mac or Mac()       # when this side may write besides the pacer (its turn)
        self.outbox = Outbox(self.pacer, one_frame=one_frame)
        self.framing = framing        # the long frame of section 2, or the short one (wire 3)
        self.decoder = framing.new_decoder(check)
        self.counters = Counters(CONNECTION_COUNTERS)

        self._sock: socket.socket | None = None      # set exactly while connected
        self._connected_at = 0.0
        self._last_rx = 0.0
        self._failures_in_outage = 0
        self._last_error = ""
        self._hold_off = False        # wait a backoff delay before the next connect attempt
        self._flaps = 0               # connections in a row that dropped before `stable_after`
        self._quiet = False           # connect/disconnect logging suspended while flapping
        self._maybe_more = False
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self._wake_r, self._wake_w = socket.socketpair()
        self._woken = False           # a wake-up byte is on its way (wake())
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)

    # -- public --------------------------------------------------------------------------------

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        return self._sock is not None and self.proof.proven

    def start(self) -> None:
        if self._thread is not None:
            raise RuntimeError(f"[{self.name}] connection already started")
        self._thread = threading.Thread(target=self._run, name=f"uwgen-link-{self.name}", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread and close the socket (idempotent)."""
        self._stopping.set()
        self.wake()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        for s in (self._wake_r, self._wake_w):
            try:
                s.close()
            except OSError:
                pass

    def wake(self) -> None:
        """Something was offered: look at the source now instead of at the next timer.

        Coalesced: one byte (one system call, one wake-up of the thread) until the thread
        has taken it, however many messages are offered meanwhile. The thread clears the
        flag before it drains the socket, so an offer after that writes again."""
        if self._woken:
            return
        self._woken = True
        try:
            self._wake_w.send(b"\0")
        except OSError:          # full (already woken) or closed (stopping)
            pass

    def stats(self) -> dict:
        d = self.decoder.stats
        o = self.outbox.stats
        c = self.counters
        return {
            "connected": self.connected,
            "frames_sent": o.frames_sent,
            "frames_received": c["frames_received"],
            "frames_dropped": {
                "abandoned": o.frames_abandoned,       # cut by a disconnect (sending side)
                "unframeable": c["unframeable"],
                "callback_errors": c["callback_errors"],
                "late": c["late_packets"],             # ready after their turn (sending side)
                "bad_length": d.bad_length,            # rejected starts (receiving side)
                "bad_terminator": d.bad_terminator,
                "stalled": d.stalled,
                "reset": d.reset,
            },
            "reconnects": c["reconnects"],
            "connects": c["connects"],
            "connect_failures": c["connect_failures"],
            "disconnects": c["disconnects"],
            "unproven": c["unproven"],
            "unserved_warnings": c["unserved_warnings"],
            "bytes_sent": o.bytes_sent,
            "bytes_received": c["bytes_received"],
            "bytes_discarded": d.bytes_discarded,
            "writes": o.writes,
        }

    # -- the thread ----------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stopping.is_set():
                if self._sock is None:
                    if self._hold_off:
                        # The last connection dropped soon after it was made: back off before
                        # trying again, or a server that accepts and closes would make us spin.
                        self._hold_off = False
                        self._stopping.wait(self.backoff.next_delay())
                        continue
                    if not self._connect():
                        self._stopping.wait(self._retry_delay())
                    continue
                try:
                    self._step()
                except OSError as e:          # includes _Closed, resets, timeouts, broken pipes
                    self._disconnect(str(e) or type(e).__name__)
        except Exception:                     # a bug: say so loudly rather than die silently
            log.exception("[%s] connection thread crashed", self.name)
            raise
        finally:
            self._close_socket()

    def _step(self) -> None:
        sock = self._sock
        assert sock is not None
        now = self.clock.now()
        batch = (self.outbox.take(now, self._pull, self._fit)
                 if self.proof.proven and self.mac.next_write_at(now) <= now else b"")
        if batch and self.mac.late(self.clock.now()):
            # the thread stalled while it built a grant or an end past its moment: written
            # now it would meet the next turn (mac_base.Mac.late); taken as lost instead
            self.outbox.abandon(counted=False)
            self.mac.abandoned()
            log_count(log, logging.WARNING, self.counters.inc("late_packets"), "[%s] a packet "
                      "built for this side's turn was not written: its turn was over when it "
                      "was ready (a stalled thread); its messages go as for a lost packet", self.name)
            batch, self._maybe_more = b"", True
        if batch:
            try:
                sock.sendall(batch, socket.MSG_NOSIGNAL)
            except OSError:
                self.outbox.abandon()
                raise
            self.outbox.sent(now)
            self.mac.wrote(now, len(batch))
            self.proof.wrote()
            self._maybe_more = self.outbox.pending or len(batch) > self.pacer.max_bytes - MIN_FRAME
        readable, _, _ = select.select([sock, self._wake_r], [], [], self._wait_time(self.clock.now()))
        if self._wake_r in readable:
            self._woken = False
            try:
                while self._wake_r.recv(4096):
                    pass
            except OSError:
                pass
        now = self.clock.now()
        if self._flaps and now - self._connected_at >= self.stable_after:
            if self._quiet:
                log.info("[%s] connection to DESERT at %s stable again after %d quick drops",
                         self.name, self.address, self._flaps)
            self._flaps, self._quiet = 0, False
        if sock in readable:
            data = sock.recv(RECV_SIZE)
            if not data:
                raise _Closed("closed by the DESERT side")
            self._last_rx = now
            self._proof_event(self.proof.received(now))
            self.counters.inc("bytes_received", len(data))
            self._deliver(self.decoder.feed(data))
        elif self.decoder.buffered and now - self._last_rx >= self.stall_timeout:
            self._deliver(self.decoder.flush())
        self._proof_event(self.proof.tick(now))
        if self._on_tick is not None:
            self._on_tick(now)

    def _wait_time(self, now: float) -> float:
        deadline = now + HOUSEKEEPING
        write_at = max(self.pacer.next_write_at, self.mac.next_write_at(now))
        if self.outbox.pending:
            deadline = min(deadline, write_at)
        elif self._next_ready is not None:
            ready = self._next_ready(now)
            if ready is not None:
                deadline = min(deadline, max(ready, write_at))
        elif self._maybe_more:
            deadline = min(deadline, write_at)
        if self.decoder.buffered:
            deadline = min(deadline, self._last_rx + self.stall_timeout)
        proof_at = self.proof.deadline()
        if proof_at is not None:
            deadline = min(deadline, proof_at)
        return max(0.0, deadline - now)

    def _pull(self, room: int | None = None) -> bytes | None:
        while True:
            now = self.clock.now()
            payload = (self._source(now) if room is None or self._source_fit is None
                       else self._source_fit(now, room - self.framing.overhead))
            if payload is None:
                return None
            try:
                return self.framing.encode(payload)
            except FrameError as e:
                log_count(log, logging.ERROR, self.counters.inc("unframeable"),
                          "[%s] dropped a payload that cannot be framed: %s", self.name, e)

    def _fit(self, room: int) -> bytes | None:
        """A frame of at most `room` bytes from `source_fit`, or None."""
        return (self._pull(room) if self._source_fit is not None and room > self.framing.overhead
                else None)

    def _deliver(self, payloads: list[bytes]) -> None:
        for p in payloads:
            self.counters.inc("frames_received")
            # one frame a packet (wire format 2): its bytes as DESERT sent them; else not known
            self.mac.arrived(len(p) + self.framing.overhead if self.outbox.one_frame else None,
                             self.clock.now())
            try:
                self._on_frame(p)
            except Exception:
                log_count(log, logging.ERROR, self.counters.inc("callback_errors"),
                          "[%s] payload handler failed; the link goes on", self.name, exc_info=True)

    # -- connection state ----------------------------------------------------------------------

    def _connect(self) -> bool:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        except OSError as e:
            self.counters.inc("connect_failures")
            self._failures_in_outage += 1
            self._last_error = str(e) or type(e).__name__
            return False
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.settimeout(self.write_timeout)
        except OSError:
            pass
        self._sock = sock
        now = self.clock.now()
        self._connected_at = self._last_rx = now
        self.proof.opened(now)
        return True

    def _proof_event(self, event: Event | None) -> None:
        if event is Event.PROVEN:
            if self.counters.inc("connects") > 1:
                self.counters.inc("reconnects")
            after = f" after {self._failures_in_outage} failed attempts" if self._failures_in_outage else ""
            if not self._quiet:
                log.info("[%s] connected to DESERT at %s%s", self.name, self.address, after)
            self._failures_in_outage = 0
        elif event is Event.UNSERVED:
            self.counters.inc("unserved_warnings")
            log.warning("[%s] connected to DESERT at %s for %.0f s and nothing has arrived although we "
                        "sent: DESERT serves one client per port, so if another client (a second "
                        "bridge, a stale process) holds this port, this one waits unserved and what it "
                        "sends goes nowhere. Stop the other client or give this one the node's own "
                        "port. If the far side simply has not sent anything yet, ignore this.",
                        self.name, self.address, self.proof.unserved_after)

    def _retry_delay(self) -> float:
        delay = self.backoff.next_delay()
        n = self._failures_in_outage
        if n <= LOUD_RETRIES:
            log.warning("[%s] cannot connect to DESERT at %s (%s); retrying in %.2f s",
                        self.name, self.address, self._last_error, delay)
        elif n == LOUD_RETRIES + 1:
            log.warning("[%s] still cannot connect to DESERT at %s (%s); retrying every <= %.1f s "
                        "without logging until connected", self.name, self.address, self._last_error,
                        self.backoff.maximum)
        return delay

    def _disconnect(self, reason: str) -> None:
        lost = self.outbox.abandon()
        self.decoder.reset()
        self._close_socket()
        if not self.proof.proven:
            # Accepted and closed at once: a DESERT shutting down or restarting. Never reported as
            # connected, so not as disconnected either; retry after a backoff delay.
            self._hold_off = True
            self._failures_in_outage += 1
            self._last_error = f"accepted, then {reason}"
            log_count(log, logging.INFO, self.counters.inc("unproven"),
                      "[%s] DESERT at %s accepted the connection and closed it before it proved itself "
                      "(%s; shutting down or restarting?); retrying", self.name, self.address, reason)
            return
        self.counters.inc("disconnects")
        cut = f"; {lost} frame(s) cut" if lost else ""
        if self.clock.now() - self._connected_at >= self.stable_after:
            self.backoff.reset()             # it worked for a while: try again at once
            self._flaps, self._quiet = 0, False
        else:
            self._hold_off = True
            self._flaps += 1
        if self._quiet:
            return
        if self._flaps > LOUD_RETRIES:
            self._quiet = True
            log.warning("[%s] connection to DESERT at %s keeps dropping (%s)%s; retrying with backoff "
                        "without logging until it holds for %.1f s", self.name, self.address, reason, cut,
                        self.stable_after)
            return
        log.warning("[%s] disconnected from DESERT at %s (%s)%s; reconnecting",
                    self.name, self.address, reason, cut)

    def _close_socket(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass
