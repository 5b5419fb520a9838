"""What the remote side of a DESERT network announced: the entities heard in beacons.

rmw_desert nodes say what they publish, subscribe, serve and call only in beacons, so
this record is all an operator of a uwgen bridge can see of them. It is fed from the
link thread and read from the ROS thread (status topic) and the CLI, hence the lock.
"""
from __future__ import annotations

import dataclasses
import logging
import threading
from dataclasses import dataclass

from uwgen.interop.beacons import Beacon, Entity, ros_type_name
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.stats import Counters

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RemoteEntity:
    """One entity a remote node announced and has not withdrawn."""

    node_name: str
    node_namespace: str
    entity: Entity
    gid: bytes
    topic: str
    type_name: str          # as announced (rmw spelling)
    first_heard: float      # clock seconds
    last_heard: float

    @property
    def node(self) -> str:
        """The node's full name, `/ns/name`."""
        ns = self.node_namespace.rstrip("/")
        return f"{ns}/{self.node_name}" if self.node_name else ns or "/"

    @property
    def ros_type(self) -> str:
        """The type in ROS spelling (pkg/msg/Name), or the raw name if it is not rmw's."""
        try:
            return ros_type_name(self.type_name)
        except ValueError:
            return self.type_name

    def as_dict(self) -> dict:
        return {
            "node": self.node,
            "entity": self.entity.name.lower(),
            "topic": self.topic,
            "type": self.ros_type,
            "gid": self.gid.hex(),
            "first_heard": self.first_heard,
            "last_heard": self.last_heard,
        }


# What observe() reports, for callers that log or count.
ADDED = "added"
REFRESHED = "refreshed"     # the same entity announced again (answer to a discovery request)
CHANGED = "changed"         # same gid, different node/topic/type: replaced
REMOVED = "removed"
UNKNOWN_DISCONNECT = "unknown_disconnect"   # a disconnect for a gid we never heard
IGNORED_OWN = "own"         # one of our own gids (an echo), not a remote entity


class RemoteGraph:
    """Remote entities by gid, as announced by beacons; removed by disconnect beacons.

    `own_gids`: gids of the entities this bridge announces itself; beacons carrying
    them are ignored, so a bridge never lists itself as remote.
    """

    def __init__(self, clock: Clock = SYSTEM_CLOCK, own_gids: frozenset[bytes] = frozenset()):
        self._clock = clock
        self._own = frozenset(own_gids)
        self._entities: dict[bytes, RemoteEntity] = {}
        self._lock = threading.Lock()
        self._counts = Counters((ADDED, REFRESHED, CHANGED, REMOVED, UNKNOWN_DISCONNECT,
                                 IGNORED_OWN))

    def observe(self, beacon: Beacon) -> str:
        """Record one heard beacon; returns what it did (ADDED, REMOVED, ...)."""
        now = self._clock.now()
        with self._lock:
            outcome, subject = self._observe(beacon, now)
            self._counts.inc(outcome)
        if subject is not None:  # a change of the graph: worth one log line
            log.info("remote %s %s %s %s (node %s)", outcome, subject.entity.name.lower(),
                     subject.topic, subject.ros_type, subject.node)
        elif outcome == UNKNOWN_DISCONNECT:
            log.debug("disconnect beacon for unknown gid %s", beacon.gid.hex())
        return outcome

    def _observe(self, beacon: Beacon, now: float) -> tuple[str, RemoteEntity | None]:
        """(outcome, the entity added/changed/removed or None); caller holds the lock."""
        gid = bytes(beacon.gid)
        if gid in self._own:
            return IGNORED_OWN, None
        old = self._entities.get(gid)
        if beacon.disconnect:
            if old is None:
                return UNKNOWN_DISCONNECT, None
            del self._entities[gid]
            return REMOVED, old
        new = RemoteEntity(beacon.node_name, beacon.node_namespace, Entity(beacon.entity),
                           gid, beacon.topic, beacon.type_name, now, now)
        if old is None:
            self._entities[gid] = new
            return ADDED, new
        if (old.node_name, old.node_namespace, old.entity, old.topic, old.type_name) == (
                new.node_name, new.node_namespace, new.entity, new.topic, new.type_name):
            self._entities[gid] = dataclasses.replace(old, last_heard=now)
            return REFRESHED, None
        # The gid now names something else: the newest announcement wins.
        self._entities[gid] = new
        return CHANGED, new

    def entities(self) -> list[RemoteEntity]:
        """Every remote entity, sorted by node, entity kind, topic (stable for display)."""
        with self._lock:
            items = list(self._entities.values())
        return sorted(items, key=lambda e: (e.node, int(e.entity), e.topic, e.gid))

    def has(self, entity: Entity, topic: str) -> bool:
        """True when some remote node announced `entity` on `topic`.

        `has(Entity.SERVICE, "/x")` is rmw_desert's `wait_for_service` condition.
        """
        with self._lock:
            return any(e.entity == entity and e.topic == topic
                       for e in self._entities.values())

    def counts(self) -> dict[str, int]:
        """How many beacons led to each outcome (JSON-able, for link stats)."""
        with self._lock:
            return self._counts.as_dict()

    def as_dict(self) -> dict:
        """JSON-able snapshot for a status topic or `uwgen` output."""
        return {"entities": [e.as_dict() for e in self.entities()],
                "beacons": self.counts()}

    def __len__(self) -> int:
        with self._lock:
            return len(self._entities)


def format_graph(entities: list[RemoteEntity]) -> str:
    """A plain table of remote entities for the terminal, one line each."""
    if not entities:
        return "no remote entities heard"
    rows = [("NODE", "ENTITY", "TOPIC/SERVICE", "TYPE")]
    rows += [(e.node, e.entity.name.lower(), e.topic, e.ros_type) for e in entities]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    return "\n".join(
        "  ".join(r[i].ljust(widths[i]) for i in range(3)) + "  " + r[3] for r in rows)
