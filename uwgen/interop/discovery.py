"""Discovery for a bridge in profile `rmw_desert`: what rmw_desert's DesertNode does.

A bridge stands in, on the DESERT network, for the ROS entities on its side: a
publisher for each topic it sends over the link, a subscriber for each it receives, a
service server for each service its side serves and a client for each it calls across
the link. rmw_desert nodes see those only through beacons, so the bridge

- sends one discovery request and all its beacons when it starts (`start()`),
- re-sends all its beacons for every discovery request it hears (`handle()`), unless a
  whole round of them is still waiting in the link's queue (that round answers it: a
  request heard while the start-up round waits for the link costs no second round),
- records the beacons it hears in a RemoteGraph (`handle()`),
- sends a disconnect beacon for each entity when it stops (`stop()`).

The agent does not own a socket: it hands unframed payloads to `send(key, payload)`
(the link's `offer`), with key 1 for beacons and 2 for the request, and is fed every
received payload that `is_discovery_payload()` accepts. Time comes from the clock only
for the graph's timestamps.
"""
from __future__ import annotations

import logging
import re
import threading
from typing import Any, Callable, Iterable

from uwgen.interop.beacons import (
    DISCOVERY_ID, DISCOVERY_REQUEST_ID, PROFILE, Beacon, BeaconError, Entity, decode_beacon,
    derive_gid, encode_beacon, encode_discovery_request, is_discovery_payload,
    is_discovery_request, rmw_type_name)
from uwgen.interop.graph import RemoteGraph
from uwgen.manifest.model import LinkPolicy, Manifest
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.stats import Counters

log = logging.getLogger(__name__)

Send = Callable[[int, bytes], bool]


def default_node_name(side: str) -> str:
    """The node name a bridge announces: the side's name (every byte of it is in every beacon,
    and a manifest's side names are valid ROS node names already), made one if it is not."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", side)
    return name if name[:1].isalpha() else "uw_" + name


def bridge_beacons(manifest: Manifest, side: str, node_name: str | None = None,
                   namespace: str = "/") -> list[Beacon]:
    """The beacons the bridge of `side` announces, in manifest order (topics, services).

    Only topics and services in profile `rmw_desert` are announced: rmw_desert nodes
    could not decode the others, and rmw_desert itself announces only names in its id
    table. Raises KeyError for an unknown side and BeaconError when a beacon would not
    fit what rmw_desert receives (names too long).
    """
    if side not in manifest.sides:
        raise KeyError(f"side {side!r} is not in manifest {manifest.network!r} "
                       f"(sides: {', '.join(manifest.sides) or 'none'})")
    return beacons_for(manifest.network, side, manifest.topics, manifest.services,
                       node_name=node_name, namespace=namespace)


def beacons_for(network: str, side: str, topics: Iterable[Any], services: Iterable[Any],
                node_name: str | None = None, namespace: str = "/") -> list[Beacon]:
    """The beacons of `side` for these topics and services, in the order given.

    Entries are duck-typed so that both the manifest (`Topic`, `Service`) and a generated
    package's codecs (`TopicCodec`, `ServiceCodec`, which is all a running bridge has)
    can be announced: topics need `name`, `type_name`, `publisher`, `profile`; services
    `name`, `type_name`, `server`, `profile`. Raises BeaconError when a beacon would not
    fit what rmw_desert receives (names too long).
    """
    node = node_name or default_node_name(side)
    beacons: list[Beacon] = []

    def add(entity: Entity, name: str, type_name: str) -> None:
        beacon = Beacon(node, namespace, entity, derive_gid(network, side, entity, name),
                        name, rmw_type_name(type_name, entity), False)
        encode_beacon(beacon)  # refuse now, not at the first discovery request
        beacons.append(beacon)

    for topic in topics:
        if getattr(topic, "profile", None) == PROFILE:
            add(Entity.PUBLISHER if topic.publisher == side else Entity.SUBSCRIBER,
                topic.name, topic.type_name)
    for service in services:
        if getattr(service, "profile", None) == PROFILE:
            add(Entity.SERVICE if service.server == side else Entity.CLIENT,
                service.name, service.type_name)
    return beacons


def discovery_policies(beacon_count: int) -> dict[int, LinkPolicy]:
    """Link channel policies for the discovery keys (1 beacons, 2 requests).

    FIFO deep enough for two full rounds of beacons (a round answering a request
    can be queued behind the start-up round), served before data because a remote
    `wait_for_service` blocks on them; never stale-dropped: beacons do not expire.
    """
    return {
        DISCOVERY_ID: LinkPolicy(queue="fifo", depth=max(4, 2 * beacon_count), priority=100, strict=True),
        DISCOVERY_REQUEST_ID: LinkPolicy(queue="latest", depth=1, priority=100, strict=True),
    }


class DiscoveryAgent:
    """Announces a bridge's beacons and listens to everyone else's (see module doc)."""

    def __init__(self, beacons: list[Beacon], send: Send, graph: RemoteGraph | None = None,
                 clock: Clock = SYSTEM_CLOCK, queued: Callable[[], int] | None = None):
        """`queued()` (optional): beacons still waiting in the link's queue (key 1)."""
        self._beacons = list(beacons)
        self._payloads = [encode_beacon(b) for b in self._beacons]
        self._goodbyes = [encode_beacon(b.gone()) for b in self._beacons]
        self._send = send
        self._queued = queued
        self.graph = graph if graph is not None else RemoteGraph(
            clock=clock, own_gids=frozenset(b.gid for b in self._beacons))
        self._lock = threading.Lock()
        self._stopped = False
        self._warned_malformed = False
        self._stats = Counters(("requests_sent", "requests_heard", "beacons_sent", "refused",
                                "beacons_heard", "malformed", "rounds_skipped"))

    @property
    def beacons(self) -> list[Beacon]:
        return list(self._beacons)

    def start(self) -> None:
        """Ask everyone for their beacons, then announce ours (what rmw_desert does)."""
        log.info("discovery: announcing %d entities and asking for remote ones",
                 len(self._beacons))
        self.announce(request=True)

    def announce(self, request: bool = False) -> None:
        """Send all beacons (and first a discovery request when `request`).

        Also for a bridge whose link reconnected: the far side may have restarted.
        Does nothing after `stop()`: announcing then would bring back entities that the
        disconnect beacons just withdrew.
        """
        if self._stopped:
            return
        if request:
            self._offer(DISCOVERY_REQUEST_ID, encode_discovery_request(), "requests_sent")
        if self._payloads and self._queued is not None and self._queued() >= len(self._payloads):
            # Rounds are queued whole, in order: the last len(beacons) waiting are a full round
            # that has not left yet, so whoever asked will hear it. Another would be air time lost.
            self._count("rounds_skipped")
            return
        for payload in self._payloads:
            self._offer(DISCOVERY_ID, payload, "beacons_sent")

    def handle(self, payload: bytes) -> bool:
        """Take a received payload; True when it was discovery traffic (kind 0, id 1/2).

        A request triggers a full round of beacons; a beacon goes to the graph; a
        malformed one is counted (and logged once), never raised.
        """
        if not is_discovery_payload(payload):
            return False
        if payload[1] == DISCOVERY_REQUEST_ID:
            if not is_discovery_request(payload):
                self._malformed("discovery request with extra items")
                return True
            self._count("requests_heard")
            self.announce(request=False)   # nothing after stop()
            return True
        try:
            beacon = decode_beacon(payload)
        except BeaconError as exc:
            self._malformed(str(exc))
            return True
        self._count("beacons_heard")
        self.graph.observe(beacon)
        return True

    def stop(self) -> None:
        """Withdraw every entity with a disconnect beacon; later requests are ignored."""
        if self._stopped:
            return
        self._stopped = True
        log.info("discovery: withdrawing %d entities", len(self._goodbyes))
        for payload in self._goodbyes:
            self._offer(DISCOVERY_ID, payload, "beacons_sent")

    def stats(self) -> dict:
        """JSON-able counters, with the graph's beacon outcomes."""
        with self._lock:
            out: dict = self._stats.as_dict()
        out["graph"] = self.graph.counts()
        out["remote_entities"] = len(self.graph)
        return out

    def _offer(self, key: int, payload: bytes, counter: str) -> None:
        if self._send(key, payload) is False:
            self._count("refused")
        else:
            self._count(counter)

    def _count(self, name: str) -> None:
        with self._lock:
            self._stats.inc(name)

    def _malformed(self, why: str) -> None:
        with self._lock:
            self._stats.inc("malformed")
            first = not self._warned_malformed
            self._warned_malformed = True
        if first:
            log.warning("discovery: dropped a malformed discovery payload (%s); further "
                        "ones are only counted", why)
