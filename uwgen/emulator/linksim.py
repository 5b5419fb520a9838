"""Two uwgen Links joined by the emulator's sans-IO core, on simulated time (no sockets, no threads).

For property tests and benchmarks that need many lossy runs fast and repeatably: the sending
Link's own scheduler, fragmenter and Outbox make the writes (exactly what its connection thread
would do when the pacer allows), EmulatorCore cuts them into packets, loses some and delivers the
rest, and the receiving Link's own decoder and reassembler turn them back into payloads.

    sim = LinkSim(scenario, "a", "b", fragment_id=250)
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=100))
    sim.at(0.0, lambda: sim.sender.offer(7, payload))
    sim.run(60.0)
    sim.received          # [(time, payload), ...] delivered at the receiving Link
"""
from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable

from uwgen.emulator.core import Delivery, EmulatorCore
from uwgen.emulator.scenario import Scenario
from uwgen.manifest.model import LinkConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.link import Link


class LinkSim:
    """Sender Link on node `src`, receiver Link on node `dst`; `run(until)` plays it out."""

    def __init__(self, scenario: Scenario, src: str, dst: str, *, step: float | None = None,
                 aligned: bool = True, **link_kw):
        self.clock = ManualClock()
        self.core = EmulatorCore(scenario)
        self.src, self.dst = src, dst
        config = LinkConfig(max_read_length=scenario.max_read_length, period=scenario.period)
        self.received: list[tuple[float, bytes]] = []
        self.packets: list[Delivery] = []
        self.sender = Link(config=config, clock=self.clock, name=src, **link_kw)
        self.receiver = Link(config=config, clock=self.clock, name=dst,
                             on_payload=lambda p: self.received.append((self.clock.now(), p)), **link_kw)
        self.sender.connection.outbox.aligned = aligned
        self.step = step if step is not None else scenario.period / 16
        self._actions: list[tuple[float, int, Callable[[], object]]] = []
        self._seq = itertools.count()
        self._last_rx = 0.0
        self.core.client_attached(src, 0.0)
        self.core.client_attached(dst, 0.0)

    def at(self, t: float, action: Callable[[], object]) -> None:
        """Run `action` (e.g. an offer) at simulated time t."""
        heapq.heappush(self._actions, (t, next(self._seq), action))

    def run(self, until: float) -> None:
        conn = self.sender.connection
        box = conn.outbox
        rx = self.receiver.connection
        t = self.clock.now()
        while t <= until:
            self.clock.set(t)
            while self._actions and self._actions[0][0] <= t:
                heapq.heappop(self._actions)[2]()
            batch = box.take(t, conn._pull, conn._fit)
            if batch:
                self.core.client_data(self.src, t, batch)
                box.sent(t)
            for d in self.core.advance(t):
                if d.node == self.dst:
                    self.packets.append(d)
                    self._last_rx = t
                    rx._deliver(rx.decoder.feed(d.data))
            if rx.decoder.buffered and t - self._last_rx >= rx.stall_timeout:
                rx._deliver(rx.decoder.flush())   # as the connection does after a silence
            self.receiver._tick(t)
            t = round(t + self.step, 9)
