"""rmw_desert discovery of one bridge (wire-format.md 6 and 6.1).

When any manifest entry is in profile `rmw_desert`, the bridge runs
`uwgen.interop.discovery.DiscoveryAgent` on link keys 1 and 2: it asks for remote beacons
and announces its own at start and again whenever its link reconnects (the far side may
have restarted), answers every discovery request with all its beacons, keeps what it
hears in a RemoteGraph (in ~/status under `discovery`; the graph logs one line per
change) and withdraws its entities with disconnect beacons at close, before the link
stops (`flush()` waits, bounded, until they have left).
"""
from __future__ import annotations

import threading
import time
from typing import Any

from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.plan import BridgePlan, PlanError
from uwgen.bridge.status import channel_stats
from uwgen.bridge.wiring import Wiring
from uwgen.interop.beacons import (DISCOVERY_ID, DISCOVERY_REQUEST_ID, DISCOVERY_REQUEST_TOPIC,
                                   DISCOVERY_TOPIC, BeaconError)
from uwgen.runtime.wire.codec import KIND_TOPIC

FLUSH_POLL = 0.01        # seconds between looks at the link while disconnect beacons leave


class RmwDiscovery:
    """Owns the DiscoveryAgent (`agent`) and its link channels, re-announce and flush."""

    def __init__(self, wiring: Wiring, plan: BridgePlan, link: Any,
                 flush_timeout: float | None = None):
        from uwgen.interop.discovery import DiscoveryAgent, beacons_for, discovery_policies
        self.w, self.link = wiring, link
        names = {DISCOVERY_ID: DISCOVERY_TOPIC, DISCOVERY_REQUEST_ID: DISCOVERY_REQUEST_TOPIC}
        taken = sorted({e.id for e in (*plan.topics, *plan.services)} & names.keys())
        if taken:
            raise PlanError(f"ids {taken} are rmw_desert's discovery topics but the manifest "
                            f"gives them to its own entries")
        # Entries rclpy cannot carry here are not bridged, so not announced either: an
        # rmw_desert client would otherwise wait for a server that never answers.
        bridged = lambda entries: [e for e in entries if e.name not in wiring.unavailable]  # noqa: E731
        try:
            beacons = beacons_for(plan.network, plan.side, bridged(plan.topics),
                                  bridged(plan.services))
        except BeaconError as exc:
            raise PlanError(f"cannot announce this side to rmw_desert nodes: {exc}") from None
        for key, policy in discovery_policies(len(beacons)).items():
            link.add_channel(key, policy, names.get(key), whole=True)   # rmw_desert reads them
        self.agent = DiscoveryAgent(beacons, send=wiring.send, clock=wiring.clock,
                                    queued=lambda: link.queued(DISCOVERY_ID))
        self.flush_timeout = (self._default_flush_timeout(beacons)
                              if flush_timeout is None else float(flush_timeout))
        self._link_connects = 0
        wiring.log.info(f"rmw_desert discovery on: announcing {len(beacons)} entities as node "
                        f"{beacons[0].node_name if beacons else '-'} (link keys 1 and 2)")

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in (DISCOVERY_ID, DISCOVERY_REQUEST_ID):
            # kind 0 on id 1 or 2: a beacon (to the graph) or a discovery request
            dispatcher.route(KIND_TOPIC, ident, lambda _ident, payload: self.agent.handle(payload))

    def _default_flush_timeout(self, beacons: list[Any]) -> float:
        """Wall-clock bound on waiting for the disconnect beacons to leave at close: the
        link's time for what the discovery queue can hold then (two rounds of beacons,
        then the disconnect beacons; 4 bytes of framing each), plus two periods; at most
        10 s. Only a bound: close() goes on as soon as the queue is empty."""
        from uwgen.interop.beacons import encode_beacon
        cfg = self.w.options.link
        size = sum(2 * (len(encode_beacon(b)) + 4) + len(encode_beacon(b.gone())) + 4
                   for b in beacons)
        writes = -(-size // max(1, cfg.max_read_length))
        return min(10.0, (writes + 2) * cfg.period * 1.1)

    def check_link(self) -> None:
        """Announce again (with a request) when the link has reconnected since last look.

        The first connection only carries what start() queued; any later one may face a
        restarted far side that has forgotten us, as rmw_desert nodes ask only at start-up.
        """
        try:
            connects = _connects(self.link.stats())
        except Exception:  # the link is shutting down
            return
        if connects is None:
            return
        if connects > max(self._link_connects, 1):
            self.w.log.info("link reconnected: asking remote nodes for their beacons and "
                            "announcing ours again")
            self.agent.announce(request=True)
        self._link_connects = max(self._link_connects, connects)

    def status(self) -> dict:
        """What this bridge announces to rmw_desert nodes and the remote graph it heard."""
        agent = self.agent
        return {
            "announced": [{"node": b.node_name, "entity": b.entity.name.lower(),
                           "topic": b.topic, "type": b.type_name} for b in agent.beacons],
            "counters": agent.stats(),
            "remote": agent.graph.as_dict()["entities"],
        }

    def stop(self) -> None:
        """Disconnect beacons, while the link still runs, and wait (bounded) for them."""
        self.agent.stop()
        if not self.flush():
            self.w.log.warning(f"disconnect beacons not all sent within "
                               f"{self.flush_timeout:g} s; remote rmw_desert nodes may "
                               "keep listing this bridge's entities")

    def flush(self) -> bool:
        """Wait (wall clock, bounded by flush_timeout) until the link has written every
        queued beacon; True when it has, or when it is not connected (nothing can leave).

        Wall clock on purpose: shutdown must end whatever an injected clock does."""
        deadline = time.monotonic() + self.flush_timeout
        waiter = threading.Event()
        while True:
            try:
                stats = self.link.stats()
            except Exception:
                return False
            if not stats.get("connected"):
                return True
            queued = channel_stats(stats).get(DISCOVERY_ID, {}).get("queued", 0)
            connection = getattr(self.link, "connection", None)
            cut = bool(getattr(getattr(connection, "outbox", None), "pending", False))
            if not queued and not cut:
                if connection is not None:
                    # The last write is in the socket; give DESERT one period to read it
                    # before the socket closes.
                    waiter.wait(min(self.w.options.link.period,
                                    max(0.0, deadline - time.monotonic())))
                return True
            if time.monotonic() >= deadline:
                return False
            waiter.wait(FLUSH_POLL)


def _connects(link_stats: Any) -> int | None:
    """How many times the link has connected (None when its stats do not say)."""
    if not isinstance(link_stats, dict):
        return None
    value = (link_stats.get("connection") or {}).get("connects")
    return value if isinstance(value, int) else None

