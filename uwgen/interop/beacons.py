"""rmw_desert discovery beacons and discovery requests (wire-format.md section 6).

rmw_desert nodes learn about remote publishers, subscribers, clients and services only
from beacons: topic messages on `/discovery` (id 1). A topic message `[0, 2]` on
`/discovery_request` (id 2) asks every node to send all its beacons again. A uwgen
bridge in profile `rmw_desert` must speak both, or an rmw_desert client's
`wait_for_service` never returns.

This module is only the byte format and the naming rules; what a bridge sends when is
in `uwgen.interop.discovery`, and what it heard is kept by `uwgen.interop.graph`.
Payloads here are unframed (no `99 99 LEN ... 55`): framing belongs to the link.
"""
from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from enum import IntEnum

import cbor2

from uwgen.manifest.model import RMW_DESERT, RMW_DISCOVERY_ID, RMW_DISCOVERY_REQUEST_ID
from uwgen.runtime.wire.codec import KIND_TOPIC, RMW_MAX_TEXT_BYTES, DecodeError, load_items
from uwgen.runtime.wire.framing import MAX_PAYLOAD    # one frame; rmw_desert wraps LEN above 255

PROFILE = RMW_DESERT        # the profile whose entries speak this format and discovery
DISCOVERY_ID = RMW_DISCOVERY_ID                  # `/discovery`: beacons
DISCOVERY_REQUEST_ID = RMW_DISCOVERY_REQUEST_ID  # `/discovery_request`: "send me your beacons again"
DISCOVERY_TOPIC = "/discovery"
DISCOVERY_REQUEST_TOPIC = "/discovery_request"

GID_SIZE = 16               # rmw's RMW_GID_STORAGE_SIZE in Jazzy
GID_BASE = 24               # derived gid bytes are 0..23: one CBOR byte each

# The whole request payload: kind 0 (topic message), id 2, no fields.
DISCOVERY_REQUEST_PAYLOAD = bytes([KIND_TOPIC, DISCOVERY_REQUEST_ID])


class Entity(IntEnum):
    """The kind of ROS entity a beacon announces (the numbers are on the wire)."""

    PUBLISHER = 0
    SUBSCRIBER = 1
    CLIENT = 2
    SERVICE = 3


class BeaconError(ValueError):
    """A beacon that cannot be encoded, or bytes that are not a beacon.

    The one error of this module: decoding any bytes either returns a Beacon or raises
    this, with `reason` saying what was wrong (and where, as an item index).
    """

    def __init__(self, reason: str):
        self.reason = reason
        super().__init__(reason)


@dataclass(frozen=True)
class Beacon:
    """One announcement: this node has (or, with `disconnect`, no longer has) this entity.

    A disconnect beacon carries empty `topic` and `type_name`, as rmw_desert sends it;
    the entity it removes is identified by `gid`.
    """

    node_name: str
    node_namespace: str
    entity: Entity
    gid: bytes
    topic: str
    type_name: str          # rmw_desert spelling: pkg__msg/Type, pkg__srv/Type_Response ...
    disconnect: bool = False

    def gone(self) -> "Beacon":
        """The disconnect beacon rmw_desert sends when this entity is destroyed."""
        return Beacon(self.node_name, self.node_namespace, self.entity, self.gid,
                      "", "", True)


# --------------------------------------------------------------------------- encode

def _text(value: str, what: str) -> bytes:
    if not isinstance(value, str):
        raise BeaconError(f"{what}: expected a string, got {type(value).__name__}")
    try:
        data = value.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise BeaconError(f"{what}: not encodable as UTF-8 ({exc.reason})") from None
    if len(data) > RMW_MAX_TEXT_BYTES:
        raise BeaconError(f"{what}: {len(data)} bytes of UTF-8, rmw_desert's receiver "
                          f"takes at most {RMW_MAX_TEXT_BYTES}")
    return cbor2.dumps(value)


def encode_beacon(beacon: Beacon) -> bytes:
    """The unframed payload of a beacon, byte for byte what rmw_desert sends.

    Refuses (BeaconError) what an rmw_desert receiver could not take: text over 127
    bytes, a payload over 255 bytes, a gid that is not 16 bytes.
    """
    try:
        entity = Entity(beacon.entity)
    except ValueError:
        raise BeaconError(f"entity: {beacon.entity!r} is not 0..3") from None
    gid = beacon.gid
    if not isinstance(gid, (bytes, bytearray)) or len(gid) != GID_SIZE:
        raise BeaconError(f"gid: expected {GID_SIZE} bytes, got {gid!r}")
    parts = [
        bytes([KIND_TOPIC, DISCOVERY_ID]),
        _text(beacon.node_name, "node_name"),
        _text(beacon.node_namespace, "node_namespace"),
        cbor2.dumps(int(entity)),
        cbor2.dumps(GID_SIZE),
        b"".join(cbor2.dumps(b) for b in gid),
        _text(beacon.topic, "topic"),
        _text(beacon.type_name, "type_name"),
        b"\xf5" if beacon.disconnect else b"\xf4",
    ]
    payload = b"".join(parts)
    if len(payload) > MAX_PAYLOAD:
        raise BeaconError(f"beacon of {beacon.topic or beacon.node_name!r} is "
                          f"{len(payload)} bytes, more than one frame ({MAX_PAYLOAD}); "
                          "shorten the node, topic or type name")
    return payload


def encode_discovery_request() -> bytes:
    """The unframed payload asking every node to send its beacons again: `00 02`."""
    return DISCOVERY_REQUEST_PAYLOAD


# --------------------------------------------------------------------------- decode

def _items(payload: bytes) -> list:
    """The CBOR sequence `payload` as a list, or BeaconError; never anything else."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise BeaconError(f"payload: expected bytes, got {type(payload).__name__}")
    if len(payload) > MAX_PAYLOAD:
        raise BeaconError(f"payload of {len(payload)} bytes is longer than one frame "
                          f"({MAX_PAYLOAD})")
    try:
        return load_items(bytes(payload))
    except DecodeError as exc:
        raise BeaconError(f"not a CBOR sequence: {exc}") from None


def _is_uint(value) -> bool:
    return type(value) is int and value >= 0  # bool is an int subclass: excluded


def _header(items: list) -> tuple[int, int]:
    if len(items) < 2 or not _is_uint(items[0]) or not _is_uint(items[1]):
        raise BeaconError("header: expected kind and id as unsigned integers")
    return items[0], items[1]


def decode_beacon(payload: bytes) -> Beacon:
    """The Beacon in an unframed `/discovery` payload; BeaconError for anything else.

    Strict about types (a bool is not an integer and an integer is not a text), except
    that `disconnect` may also be the integer 0 or 1, as every uwgen bool decoder allows.
    """
    items = _items(payload)
    kind, ident = _header(items)
    if kind != KIND_TOPIC or ident != DISCOVERY_ID:
        raise BeaconError(f"header: kind {kind} id {ident} is not a beacon "
                          f"(kind {KIND_TOPIC} id {DISCOVERY_ID})")
    expected = 2 + 4 + GID_SIZE + 3
    pos = 2

    def take(what: str):
        nonlocal pos
        if pos >= len(items):
            raise BeaconError(f"item {pos} ({what}): missing")
        value = items[pos]
        pos += 1
        return value

    def text(what: str) -> str:
        value = take(what)
        if type(value) is not str:
            raise BeaconError(f"item {pos - 1} ({what}): expected text, "
                              f"got {type(value).__name__}")
        return value

    node_name = text("node_name")
    node_namespace = text("node_namespace")
    raw_entity = take("entity")
    if not _is_uint(raw_entity) or raw_entity > 3:
        raise BeaconError(f"item {pos - 1} (entity): expected 0..3, got {raw_entity!r}")
    count = take("gid count")
    if count != GID_SIZE or not _is_uint(count):
        raise BeaconError(f"item {pos - 1} (gid count): expected {GID_SIZE}, got {count!r}")
    gid = bytearray()
    for i in range(GID_SIZE):
        byte = take(f"gid[{i}]")
        if not _is_uint(byte) or byte > 0xFF:
            raise BeaconError(f"item {pos - 1} (gid[{i}]): expected 0..255, got {byte!r}")
        gid.append(byte)
    topic = text("topic")
    type_name = text("type_name")
    flag = take("disconnect")
    if type(flag) is bool:
        disconnect = flag
    elif type(flag) is int and flag in (0, 1):
        disconnect = bool(flag)
    else:
        raise BeaconError(f"item {pos - 1} (disconnect): expected a bool, got {flag!r}")
    if len(items) != expected:
        raise BeaconError(f"{len(items) - expected} item(s) left over after the beacon")
    return Beacon(node_name, node_namespace, Entity(raw_entity), bytes(gid), topic,
                  type_name, disconnect)


def is_discovery_request(payload: bytes) -> bool:
    """True when `payload` is exactly a discovery request ([0, 2], no fields)."""
    try:
        items = _items(payload)
    except BeaconError:
        return False
    return (len(items) == 2 and _is_uint(items[0]) and _is_uint(items[1])
            and items[0] == KIND_TOPIC and items[1] == DISCOVERY_REQUEST_ID)


def is_discovery_payload(payload: bytes) -> bool:
    """Cheap test a receiver can run first: kind 0 with id 1 or 2 (shortest CBOR form)."""
    return len(payload) >= 2 and payload[0] == KIND_TOPIC and payload[1] in (
        DISCOVERY_ID, DISCOVERY_REQUEST_ID)


# --------------------------------------------------------------------------- naming

_ROS_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(msg|srv)/([A-Za-z][A-Za-z0-9_]*)$")
_RMW_TYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*?)__(msg|srv)/([A-Za-z][A-Za-z0-9_]*)$")


def rmw_type_name(type_name: str, entity: Entity | None = None) -> str:
    """rmw_desert's spelling of a ROS type for a beacon of `entity`.

    `pkg/msg/Type` -> `pkg__msg/Type`; a service `pkg/srv/Type` -> `pkg__srv/Type_Response`
    for its server (Entity.SERVICE) and `pkg__srv/Type_Request` for a client
    (Entity.CLIENT), because rmw_desert announces the type it receives.
    """
    match = _ROS_TYPE.match(type_name)
    if not match:
        raise ValueError(f"type {type_name!r}: expected pkg/msg/Name or pkg/srv/Name")
    package, namespace, name = match.groups()
    if namespace == "msg":
        if entity in (Entity.CLIENT, Entity.SERVICE):
            raise ValueError(f"type {type_name!r} is a message; a {entity.name.lower()} "
                             "needs a service type")
        return f"{package}__msg/{name}"
    if entity is Entity.SERVICE:
        return f"{package}__srv/{name}_Response"
    if entity is Entity.CLIENT:
        return f"{package}__srv/{name}_Request"
    raise ValueError(f"type {type_name!r} is a service; say whether the beacon is for a "
                     "client or a service server")


def ros_type_name(rmw_name: str) -> str:
    """The ROS spelling of a beacon's type name: the inverse of rmw_type_name.

    `pkg__msg/Type` -> `pkg/msg/Type`; `pkg__srv/Type_Request` and `..._Response` ->
    `pkg/srv/Type`. Raises ValueError for anything else.
    """
    match = _RMW_TYPE.match(rmw_name)
    if not match:
        raise ValueError(f"type {rmw_name!r}: expected pkg__msg/Name or pkg__srv/Name_Request"
                         " or pkg__srv/Name_Response")
    package, namespace, name = match.groups()
    if namespace == "srv":
        for suffix in ("_Request", "_Response"):
            if name.endswith(suffix) and len(name) > len(suffix):
                name = name[: -len(suffix)]
                break
        else:
            raise ValueError(f"type {rmw_name!r}: a service type ends in _Request or "
                             "_Response")
    return f"{package}/{namespace}/{name}"


def derive_gid(network: str, side: str, entity: Entity, name: str) -> bytes:
    """A stable 16-byte gid for an entity a bridge stands in for.

    Stable across restarts (so a restarted bridge re-announces the same entities and a
    disconnect beacon from before the restart still matches), distinct per network,
    side, entity kind and name. rmw gids from real nodes are random-looking, so a
    hash is as good a namespace as any. Each gid byte is one base-24 digit of the hash
    (0..23): a beacon carries the gid as 16 CBOR integers, and values under 24 take one
    byte each instead of two, so a beacon is 14 bytes shorter (it then fits a 64-byte
    DESERT packet more often). 24^16 is about 2^73: collisions are 2^-36 for a birthday pair.
    """
    key = "\x00".join(("uwgen-gid-v2", network, side, str(int(Entity(entity))), name))
    n = int.from_bytes(hashlib.sha256(key.encode("utf-8")).digest(), "big")
    digits = []
    for _ in range(GID_SIZE):
        n, d = divmod(n, GID_BASE)
        digits.append(d)
    return bytes(digits)
