"""The emulator's socket shell: DESERT's TCP application sockets around the sans-IO core.

An asyncio loop in a background thread listens on one port per node (127.0.0.1 only),
feeds what clients write into `EmulatorCore`, writes the core's deliveries back to the
destination node's client, and wakes up exactly when the core's next event is due.
Simulated time is seconds since the emulator started, on the loop's monotonic clock.

Like DESERT's UW/APPLICATION, each node serves one client at a time: a second client's
connection is accepted by the kernel but not read from (nor written to) until the first
one disconnects.  `restart()` behaves like killing and restarting DESERT: every socket is
closed, queued and in-flight packets are lost, and the same ports listen again. `hold()` keeps
what the medium delivers to a node for some seconds before writing it to its client (an
attacker's store-and-forward, a relay: the delay series of docs/seams.md section 8).

    with run_emulator(scenario) as emu:
        port = emu.port("vehicle"); emu.counters("vehicle"); emu.restart(delay=0.5)
"""
from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections import deque
from typing import Callable

from uwgen.emulator.core import Delivery, EmulatorCore
from uwgen.emulator.scenario import Scenario

log = logging.getLogger("uwgen.emulator")

HOST = "127.0.0.1"


class EmulatorError(RuntimeError):
    """The emulator could not start (a port is taken, ...) or was used after stop()."""


class _Client(asyncio.Protocol):
    """One TCP connection to a node's port."""

    def __init__(self, emu: "Emulator", node: str):
        self.emu = emu
        self.node = node
        self.transport: asyncio.Transport | None = None
        self.peer = "?"
        self.early: list[bytes] = []   # read before it was served (should not happen: paused)

    def connection_made(self, transport) -> None:  # type: ignore[override]
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        self.emu._on_connect(self)

    def data_received(self, data: bytes) -> None:
        self.emu._on_data(self, data)

    def eof_received(self) -> bool:
        return False  # DESERT shuts the socket down when read() returns 0

    def connection_lost(self, exc) -> None:
        self.emu._on_disconnect(self)


class _NodeSocket:
    """A node's listening socket and its clients: the served one and those waiting."""

    def __init__(self, name: str, port: int):
        self.name = name
        self.port = port
        self.server: asyncio.base_events.Server | None = None
        self.active: _Client | None = None
        self.waiting: deque[_Client] = deque()


class Emulator:
    """N emulated DESERT nodes on 127.0.0.1, run by a background thread (see module doc)."""

    def __init__(self, scenario: Scenario, record: bool = False):
        self.scenario = scenario
        self._core = EmulatorCore(scenario)
        self._record = record
        self._delivered: list[Delivery] = []
        self._lock = threading.Lock()
        self._nodes = {n.name: _NodeSocket(n.name, n.port) for n in scenario.nodes}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._t0 = 0.0
        self._timer: asyncio.TimerHandle | None = None
        self._listening = threading.Event()
        self._stopped = False
        self._holds: dict[str, list[list[float]]] = {}   # node -> [[seconds, until, count]]
        self._held: dict[str, int] = {}                  # node -> deliveries held so far

    # ------------------------------------------------------------------ public API
    def start(self) -> "Emulator":
        """Bind every port, then serve in a background thread. Raises EmulatorError if a port
        cannot be bound. With scenario.start_delay the ports are bound at once (so port()
        works) but accept connections only after the delay, like DESERT's start time."""
        if self._thread is not None:
            raise EmulatorError("emulator already started")
        socks = {}
        try:
            for ns in self._nodes.values():
                socks[ns.name] = _bind(ns.name, ns.port)
                ns.port = socks[ns.name].getsockname()[1]
        except EmulatorError:
            for s in socks.values():
                s.close()
            raise
        self._loop = asyncio.new_event_loop()
        started = threading.Event()
        failure: list[BaseException] = []

        def run() -> None:
            asyncio.set_event_loop(self._loop)
            try:
                self._t0 = self._loop.time()
                self._loop.run_until_complete(self._open(socks, self.scenario.start_delay))
            except BaseException as exc:  # noqa: BLE001 - reported to start()
                failure.append(exc)
                started.set()
                return
            started.set()
            self._loop.run_forever()
            self._loop.run_until_complete(self._loop.shutdown_asyncgens())
            self._loop.close()

        self._thread = threading.Thread(target=run, name="uwgen-emulator", daemon=True)
        self._thread.start()
        started.wait()
        if failure:
            raise EmulatorError(f"emulator failed to start: {failure[0]}") from failure[0]
        return self

    def port(self, node: str) -> int:
        """The TCP port `node` listens on (the real one when the scenario said 0)."""
        return self._socket(node).port

    def ports(self) -> dict[str, int]:
        return {name: ns.port for name, ns in self._nodes.items()}

    def counters(self, node: str) -> dict[str, int]:
        """A snapshot of `node`'s counters (see EmulatorCore; thread-safe)."""
        self._socket(node)
        with self._lock:
            return self._core.counters(node)

    def all_counters(self) -> dict[str, dict[str, int]]:
        with self._lock:
            return self._core.all_counters()

    def set_position(self, node: str, position) -> None:
        """Move `node` to `position` (x, y, z metres) now; packets it sends or receives from
        now on use it (thread-safe; a live pose, see uwgen.emulator.ros_pose)."""
        self._socket(node)
        loop = self._require_loop()
        with self._lock:
            self._core.set_position(node, self._now(), position)
        loop.call_soon_threadsafe(self._pump)     # deliveries due by now go out at once

    def position(self, node: str) -> tuple[float, float, float]:
        """Where `node` is now (fixed, on its waypoints, or its latest live position)."""
        self._socket(node)
        with self._lock:
            return self._core.position(node, self._now() if self._loop else 0.0)

    def hold(self, node: str, seconds: float, *, window: float = 0.0, count: int = 0) -> None:
        """Hold what the medium delivers to `node` `seconds` before writing it to its client:
        every delivery within `window` seconds from now, or the next `count` ones. A held
        delivery is written when its time comes if a client is connected then, else lost."""
        self._socket(node)
        if seconds < 0 or window < 0 or count < 0 or not (window or count):
            raise ValueError("hold: seconds >= 0 and a window or a count > 0")
        self._require_loop()
        with self._lock:
            until = self._now() + window if window else float("inf")
            self._holds.setdefault(node, []).append([seconds, until, count or float("inf")])

    def held(self, node: str) -> int:
        """How many deliveries to `node` were held so far."""
        with self._lock:
            return self._held.get(node, 0)

    def _held_for(self, node: str, now: float) -> float | None:
        """Seconds the delivery to `node` arriving now is held (None: not held); under lock."""
        holds = self._holds.get(node)
        if not holds:
            return None
        holds[:] = [h for h in holds if h[1] >= now and h[2] > 0]
        if not holds:
            return None
        h = holds[0]
        h[2] -= 1
        self._held[node] = self._held.get(node, 0) + 1
        return h[0]

    def _release(self, d: Delivery) -> None:
        ns = self._nodes[d.node]
        if ns.active is not None and ns.active.transport is not None:
            ns.active.transport.write(d.data)

    def deliveries(self, node: str | None = None) -> list[Delivery]:
        """Every packet written to a client so far (to `node`'s, or to any), in order. Kept only
        when the emulator was made with record=True (tests use it to know what was lost)."""
        if not self._record:
            raise EmulatorError("deliveries are kept only with Emulator(..., record=True)")
        with self._lock:
            return [d for d in self._delivered if node is None or d.node == node]

    @property
    def restarts(self) -> int:
        with self._lock:
            return self._core.restarts

    def wait_listening(self, timeout: float | None = None) -> bool:
        """Block until every port accepts connections (after a start delay or a restart)."""
        return self._listening.wait(timeout)

    def restart(self, delay: float = 0.0, wait: bool = True) -> None:
        """Kill and restart DESERT: clients are disconnected, packets queued or in flight are
        lost, and the same ports listen again after `delay` seconds. With wait=False it
        returns at once (use wait_listening())."""
        loop = self._require_loop()
        self._listening.clear()
        fut = asyncio.run_coroutine_threadsafe(self._restart(delay), loop)
        if wait:
            fut.result()

    def stop(self) -> None:
        """Close every socket and stop the thread. Counters stay readable."""
        if self._stopped or self._loop is None or self._thread is None:
            self._stopped = True
            return
        self._stopped = True
        loop = self._loop
        try:
            asyncio.run_coroutine_threadsafe(self._close_all(), loop).result(timeout=5)
        except Exception:  # noqa: BLE001 - shutting down anyway
            log.exception("emulator: error while closing sockets")
        loop.call_soon_threadsafe(loop.stop)
        self._thread.join(timeout=5)

    def __enter__(self) -> "Emulator":
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ loop side
    def _now(self) -> float:
        assert self._loop is not None
        return self._loop.time() - self._t0

    async def _open(self, socks: dict[str, socket.socket], delay: float) -> None:
        if delay > 0:
            log.info("emulator: DESERT starts in %.2f s", delay)
            self._loop.call_later(delay, lambda: asyncio.ensure_future(self._listen(socks)))
            return
        await self._listen(socks)

    async def _listen(self, socks: dict[str, socket.socket]) -> None:
        loop = asyncio.get_running_loop()
        for name, sock in socks.items():
            ns = self._nodes[name]
            ns.server = await loop.create_server(self._factory(name), sock=sock)
            log.info("node %s: listening on %s:%d (sends to %s)", name, HOST, ns.port,
                     self.scenario.dest_of(name))
        self._listening.set()

    def _factory(self, name: str) -> Callable[[], _Client]:
        return lambda: _Client(self, name)

    async def _restart(self, delay: float) -> None:
        self._pump()
        await self._close_all()
        with self._lock:
            self._core.reset(self._now())
        log.info("emulator: restarted (queues and packets in flight dropped)%s",
                 f", listening again in {delay:.2f} s" if delay > 0 else "")
        if delay > 0:
            await asyncio.sleep(delay)
        socks = {}
        for ns in self._nodes.values():
            socks[ns.name] = _bind(ns.name, ns.port)
        await self._listen(socks)

    async def _close_all(self) -> None:
        self._listening.clear()
        for ns in self._nodes.values():
            if ns.server is not None:
                ns.server.close()
            clients = ([ns.active] if ns.active else []) + list(ns.waiting)
            if ns.active is not None:
                with self._lock:
                    self._core.client_detached(ns.name, self._now())
                log.info("node %s: client %s disconnected by the emulator", ns.name,
                         ns.active.peer)
            ns.active = None
            ns.waiting.clear()
            for c in clients:
                # Like a killed process: what was written is flushed, then the socket closes.
                if c.transport is not None:
                    c.transport.close()
        for ns in self._nodes.values():
            if ns.server is not None:
                await ns.server.wait_closed()
                ns.server = None
        await asyncio.sleep(0)   # let connection_lost callbacks run
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _on_connect(self, client: _Client) -> None:
        ns = self._nodes[client.node]
        if ns.active is None:
            self._activate(ns, client)
        else:
            # DESERT accepts the next client only when the current one leaves.
            client.transport.pause_reading()
            ns.waiting.append(client)
            log.info("node %s: client %s waits (node busy with %s)", ns.name, client.peer,
                     ns.active.peer)

    def _activate(self, ns: _NodeSocket, client: _Client) -> None:
        self._pump()
        ns.active = client
        with self._lock:
            self._core.client_attached(ns.name, self._now())
        client.transport.resume_reading()
        log.info("node %s: client %s connected", ns.name, client.peer)
        early, client.early = client.early, []
        for data in early:
            self._on_data(client, data)

    def _on_data(self, client: _Client, data: bytes) -> None:
        ns = self._nodes[client.node]
        if ns.active is not client:
            # A waiting client's reading is paused; anything that slipped through is kept
            # for when it is served, never dropped.
            client.early.append(data)
            return
        with self._lock:
            # client_data runs the core up to now first; the pump below writes every
            # delivery that produced, in order, and re-arms the timer once.
            self._core.client_data(ns.name, self._now(), data)
        self._pump()

    def _on_disconnect(self, client: _Client) -> None:
        ns = self._nodes[client.node]
        if ns.active is client:
            self._pump()
            ns.active = None
            with self._lock:
                self._core.client_detached(ns.name, self._now())
            log.info("node %s: client %s disconnected", ns.name, client.peer)
            while ns.waiting:
                nxt = ns.waiting.popleft()
                if nxt.transport is not None and not nxt.transport.is_closing():
                    self._activate(ns, nxt)
                    break
        elif client in ns.waiting:
            ns.waiting.remove(client)

    def _pump(self) -> None:
        """Run the core up to now, write what it delivered, and sleep until its next event."""
        if self._loop is None or self._loop.is_closed():
            return
        with self._lock:
            now = self._now()
            deliveries = self._core.advance(now)
            nxt = self._core.next_event_time()
            if self._record:
                self._delivered.extend(deliveries)
            held = [self._held_for(d.node, now) for d in deliveries]
        for d, seconds in zip(deliveries, held):
            if seconds is not None:
                self._loop.call_later(seconds, self._release, d)
                continue
            ns = self._nodes[d.node]
            if ns.active is not None and ns.active.transport is not None:
                ns.active.transport.write(d.data)
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if nxt is not None:
            self._timer = self._loop.call_at(self._t0 + nxt, self._pump)

    # ------------------------------------------------------------------ helpers
    def _socket(self, node: str) -> _NodeSocket:
        try:
            return self._nodes[node]
        except KeyError:
            raise KeyError(f"no node named {node!r} (nodes: {', '.join(self._nodes)})") from None

    def _require_loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None or self._stopped:
            raise EmulatorError("emulator is not running")
        return self._loop


def _bind(name: str, port: int) -> socket.socket:
    """A TCP socket bound to 127.0.0.1:port with SO_REUSEADDR (so a restart gets the same
    port back at once), not yet listening."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((HOST, port))
    except OSError as exc:
        sock.close()
        raise EmulatorError(f"node {name}: cannot listen on {HOST}:{port}: "
                            f"{exc.strerror or exc}") from None
    sock.setblocking(False)
    return sock


def run_emulator(scenario: Scenario, record: bool = False) -> Emulator:
    """Start an emulator for `scenario`; use it as a context manager to stop it."""
    return Emulator(scenario, record=record).start()
