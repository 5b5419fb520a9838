"""Two uwgen Links talking both ways through the emulator's sans-IO core, on simulated time.

LinkSim (uwgen.emulator.linksim) sends one way; acknowledgements (docs/wire-format.md
section 15) need the other way too. Here each side's Link both sends and receives, as its
connection thread would: when the pacer allows a write, the outbox's batch (pulled from
the link's packer) goes to the emulated DESERT node; what the node delivers goes to the
link's decoder; each turn the link's housekeeping runs. A side writes only when its
link's MAC allows it too (`Link(mac=...)`, through `link_kw_for`), as the connection does.

    sim = DuplexSim(scenario, ("a", "b"), wire_format=2, hooks_for=lambda side: ...)
    sim.links["a"].add_channel(7, LinkPolicy(queue="fifo", depth=100, reliable=True, ttl=30))
    sim.at(0.0, lambda: sim.links["a"].offer(7, payload))
    sim.run(60.0)
    sim.received["b"]      # [(time, payload), ...] delivered at b's Link

`drop(side, n)` loses the n-th packet (0-based, counted per sending side) whatever the
channel does: for tests that lose one given packet. `hold(side, seconds, n...)` holds those
packets back that long before they reach the channel (a frame recorded and released later).
"""
from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable
from typing import Any

from uwgen.emulator.core import EmulatorCore
from uwgen.emulator.scenario import Scenario
from uwgen.manifest.model import LinkConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.link import Link


class DuplexSim:
    def __init__(self, scenario: Scenario, sides: tuple[str, str], *,
                 hooks_for: Callable[[str], Any] | None = None,
                 link_kw_for: Callable[[str], dict] | None = None, step: float | None = None,
                 clock: ManualClock | None = None, **link_kw: Any):
        self.clock = clock or ManualClock()
        self.core = EmulatorCore(scenario)
        self.sides = sides
        config = LinkConfig(max_read_length=scenario.max_read_length, period=scenario.period)
        self.received: dict[str, list[tuple[float, bytes]]] = {s: [] for s in sides}
        self.links: dict[str, Link] = {}
        self._make = (config, hooks_for, link_kw_for, link_kw)
        self.written: dict[str, int] = {s: 0 for s in sides}
        self._drops: dict[str, set[int]] = {s: set() for s in sides}
        self._holds: dict[str, dict[int, float]] = {s: {} for s in sides}
        for side in sides:
            self._start(side)
            self.core.client_attached(side, 0.0)
        self.step = step if step is not None else scenario.period / 8
        self._actions: list[tuple[float, int, Callable[[], object]]] = []
        self._seq = itertools.count()
        self._last_rx = {s: 0.0 for s in sides}

    def _start(self, side: str) -> Link:
        config, hooks_for, link_kw_for, link_kw = self._make
        kw = dict(link_kw)
        kw.setdefault("sender_id", self.sides.index(side) + 1)
        if hooks_for is not None:
            kw["hooks"] = hooks_for(side)
        if link_kw_for is not None:
            kw.update(link_kw_for(side))
        link = self.links[side] = Link(config=config, clock=self.clock, name=side,
                                       on_payload=lambda p, s=side: self.received[s].append(
                                           (self.clock.now(), p)), **kw)
        link.connection.outbox.aligned = True
        return link

    def restart(self, side: str) -> Link:
        """`side`'s process starts again: a new Link (and hooks), nothing kept in memory."""
        return self._start(side)

    def at(self, t: float, action: Callable[[], object]) -> None:
        heapq.heappush(self._actions, (t, next(self._seq), action))

    def drop(self, side: str, *writes: int) -> None:
        """Lose the given writes (0-based) of `side` before they reach the emulator."""
        self._drops[side].update(writes)

    def hold(self, side: str, seconds: float, *writes: int) -> None:
        """Hold the given writes (0-based) of `side` `seconds` before they reach the emulator."""
        self._holds[side].update({n: seconds for n in writes})

    def run(self, until: float) -> None:
        t = self.clock.now()
        while t <= until:
            self.clock.set(t)
            while self._actions and self._actions[0][0] <= t:
                heapq.heappop(self._actions)[2]()
            for side, link in self.links.items():
                conn = link.connection
                if link.mac.next_write_at(t) > t:     # not this side's turn (runtime.link.mac)
                    continue
                batch = conn.outbox.take(t, conn._pull, conn._fit)
                if batch:
                    link.mac.wrote(t, len(batch))
                    n = self.written[side]
                    self.written[side] += 1
                    held = self._holds[side].get(n)
                    if held is not None:
                        self.at(t + held, lambda s=side, b=batch: self.core.client_data(
                            s, self.clock.now(), b))
                    elif n not in self._drops[side]:
                        self.core.client_data(side, t, batch)
                    conn.outbox.sent(t)
            for d in self.core.advance(t):
                conn = self.links[d.node].connection
                self._last_rx[d.node] = t
                conn._deliver(conn.decoder.feed(d.data))
            for side, link in self.links.items():
                conn = link.connection
                if conn.decoder.buffered and t - self._last_rx[side] >= conn.stall_timeout:
                    conn._deliver(conn.decoder.flush())
                link._tick(t)
            t = round(t + self.step, 9)
