#!/usr/bin/env python3
"""A stand-in for an rmw_desert node, written from wire-format.md section 6 only.

It is deliberately independent of uwgen: no uwgen import, its own CBOR writer and
reader, and a REFLECTIVE serializer that walks rclpy message introspection
(`get_fields_and_field_types()` / `SLOT_TYPES`) and applies rmw_desert's rules. Tests
compare it with uwgen's generated `rmw_desert` codecs, and run it as a process against
a bridge over the DESERT emulator, so a mistake in either shows up as a mismatch.

rmw_desert rules it applies (section 6):
- bool is F4/F5; it accepts nothing else for a bool;
- float32 and float64 are narrowed to float32, then written as half (F9) when the half
  converts back exactly, else single (FA); never double (FB, refused on receive);
- byte/octet fields are neither written nor read (scalar, fixed array, sequence);
- uint8/char arrays and sequences go element by element (a sequence with its count);
- fixed arrays carry no count, except fixed arrays of string/wstring;
- a message with no fields is the single item 00 (rosidl's dummy member);
- on receive: at most 64 items, text at most 127 bytes, payload at most 512 bytes;
  unknown ids are ignored; a kind other than 0/2/3 is reported as fatal (it kills a real
  rmw_desert node);
- a client picks seq in 0..999 and accepts the first response with that seq; a server
  answers with the request's seq;
- discovery: one discovery request `[0, 2]` at start, beacons for its entities, beacons
  again for every request heard, disconnect beacons at exit.
Frames are `99 99 LEN payload 55` with LEN wrapped modulo 256, as rmw_desert does.

Command line (JSON lines on stdout, one per event; see `--help`):
    DESERT_PORT=4001 ROS_ALLOWED_TOPICS_CONFIG=ids.json \
      python rmw_desert_peer.py --node teleop --pub /turtle1/cmd_vel=geometry_msgs/msg/Twist \
        --data /turtle1/cmd_vel='{"linear": {"x": 2.0}}' --count 3 --rate 5 \
        --sub /turtle1/pose=turtlesim/msg/Pose --expect /turtle1/pose=1 \
        --call /spawn=std_srvs/srv/SetBool --data /spawn='{"data": true}' --until-done
"""
from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import random
import select
import socket
import struct
import sys
import time
from dataclasses import dataclass, field
from typing import Any

KIND_TOPIC, KIND_REQUEST, KIND_RESPONSE = 0, 2, 3
DISCOVERY_ID, DISCOVERY_REQUEST_ID = 1, 2
PUBLISHER, SUBSCRIBER, CLIENT, SERVICE = 0, 1, 2, 3
ENTITY_NAMES = {PUBLISHER: "publisher", SUBSCRIBER: "subscriber", CLIENT: "client",
                SERVICE: "service"}
MAX_ITEMS = 64
MAX_TEXT = 127
MAX_RX_PAYLOAD = 512


class PeerError(ValueError):
    """Anything the peer cannot encode or decode; `path` names the field."""

    def __init__(self, message: str, path: str = ""):
        self.path = path
        super().__init__(f"{path}: {message}" if path else message)


# ============================================================================ CBOR writer

def _head(major: int, n: int) -> bytes:
    if n < 24:
        return bytes([major << 5 | n])
    for extra, size in ((24, 1), (25, 2), (26, 4), (27, 8)):
        if n < 1 << (8 * size):
            return bytes([major << 5 | extra]) + n.to_bytes(size, "big")
    raise PeerError(f"integer {n} does not fit 64 bits")


def cbor_int(n: int) -> bytes:
    return _head(0, n) if n >= 0 else _head(1, -1 - n)


def cbor_text(s: str) -> bytes:
    data = s.encode("utf-8")
    return _head(3, len(data)) + data


def cbor_bool(b: bool) -> bytes:
    return b"\xf5" if b else b"\xf4"


def narrow_to_float32(x: float) -> float:
    """What a C cast double -> float gives: round to nearest, overflow to infinity."""
    if math.isnan(x) or math.isinf(x):
        return x
    try:
        return struct.unpack("<f", struct.pack("<f", x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


def cbor_float_rmw(x: float) -> bytes:
    """rmw_desert float: narrowed to float32, half when exact, else single."""
    if math.isnan(x):
        return b"\xf9\x7e\x00"
    f = narrow_to_float32(float(x))
    try:
        half = struct.pack(">e", f)
        if struct.unpack(">e", half)[0] == f:
            return b"\xf9" + half
    except OverflowError:
        pass
    return b"\xfa" + struct.pack(">f", f)


# ============================================================================ CBOR reader

@dataclass(frozen=True)
class Item:
    """One decoded CBOR item, with its form kept (so FB or a non-bool can be refused)."""

    kind: str        # uint, nint, text, bytes, bool, half, single, double, other
    value: Any


def read_items(payload: bytes) -> list[Item]:
    """The payload as a list of top-level items; PeerError on anything malformed.

    Only what rmw_desert sends is understood; arrays, maps and tags are "other".
    """
    items: list[Item] = []
    pos = 0
    n = len(payload)
    while pos < n:
        ib = payload[pos]
        pos += 1
        major, info = ib >> 5, ib & 0x1F
        if major == 7:
            if info == 20 or info == 21:
                items.append(Item("bool", info == 21))
                continue
            widths = {25: (2, ">e", "half"), 26: (4, ">f", "single"), 27: (8, ">d", "double")}
            if info in widths:
                size, fmt, kind = widths[info]
                if pos + size > n:
                    raise PeerError(f"truncated float at offset {pos - 1}")
                items.append(Item(kind, struct.unpack(fmt, payload[pos:pos + size])[0]))
                pos += size
                continue
            if info < 24:
                items.append(Item("other", ("simple", info)))
                continue
            raise PeerError(f"unsupported simple/float byte 0x{ib:02X} at offset {pos - 1}")
        if info < 24:
            arg = info
        elif info in (24, 25, 26, 27):
            size = 1 << (info - 24)
            if pos + size > n:
                raise PeerError(f"truncated item head at offset {pos - 1}")
            arg = int.from_bytes(payload[pos:pos + size], "big")
            pos += size
        else:
            raise PeerError(f"indefinite or reserved length 0x{ib:02X} at offset {pos - 1}")
        if major == 0:
            items.append(Item("uint", arg))
        elif major == 1:
            items.append(Item("nint", -1 - arg))
        elif major in (2, 3):
            if arg > n - pos:
                raise PeerError(f"string of {arg} bytes at offset {pos} overruns the payload")
            data = payload[pos:pos + arg]
            pos += arg
            if major == 2:
                items.append(Item("bytes", data))
            else:
                try:
                    items.append(Item("text", data.decode("utf-8")))
                except UnicodeDecodeError:
                    raise PeerError(f"text at offset {pos - arg} is not UTF-8") from None
        else:
            # Arrays, maps and tags never appear in rmw_desert payloads.
            items.append(Item("other", (major, arg)))
            if major in (4, 5):
                raise PeerError(f"array/map at offset {pos - 1}: rmw_desert never sends one")
    return items


# ============================================================================ introspection

def _definition():
    from rosidl_parser import definition  # part of any ROS 2 Python install
    return definition


def import_type(name: str):
    """The rclpy class for `pkg/msg/Name` or `pkg/srv/Name` (also `pkg/Name` for msgs)."""
    parts = name.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or parts[1] not in ("msg", "srv"):
        raise PeerError(f"type {name!r}: expected pkg/msg/Name or pkg/srv/Name")
    try:
        module = importlib.import_module(f"{parts[0]}.{parts[1]}")
        return getattr(module, parts[2])
    except (ImportError, AttributeError):
        raise PeerError(f"type {name!r} is not installed for Python") from None


def fields_of(cls) -> list[tuple[str, Any]]:
    """(name, rosidl type) of every member, in declaration order."""
    names = list(cls.get_fields_and_field_types())
    slots = list(cls.SLOT_TYPES)
    if len(names) != len(slots):  # pragma: no cover - would be an rclpy bug
        raise PeerError(f"{cls.__name__}: fields and SLOT_TYPES disagree")
    return list(zip(names, slots))


def _nested_class(t):
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


_INT_RANGES = {
    "int8": (-2**7, 2**7 - 1), "uint8": (0, 2**8 - 1), "char": (0, 2**8 - 1),
    "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1), "short": (-2**15, 2**15 - 1),
    "unsigned short": (0, 2**16 - 1), "int32": (-2**31, 2**31 - 1),
    "uint32": (0, 2**32 - 1), "long": (-2**31, 2**31 - 1), "unsigned long": (0, 2**32 - 1),
    "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1), "long long": (-2**63, 2**63 - 1),
    "unsigned long long": (0, 2**64 - 1), "wchar": (0, 2**16 - 1),
}
_FLOATS = ("float", "double", "long double")


def _min_items(t) -> int:
    """Fewest CBOR items one value of `t` takes (0 only for all-byte messages)."""
    d = _definition()
    if _is_octet(t):
        return 0
    if isinstance(t, d.NamespacedType):
        members = fields_of(_nested_class(t))
        if not members:
            return 1
        return sum(_min_items(m) if not isinstance(m, d.AbstractNestedType) else
                   (0 if _is_octet(m.value_type) else
                    (m.size * _min_items(m.value_type) if isinstance(m, d.Array)
                     and not _is_stringish(m.value_type) else 1))
                   for _, m in members)
    return 1


def _is_octet(t) -> bool:
    d = _definition()
    return isinstance(t, d.BasicType) and t.typename == "octet"


def _is_stringish(t) -> bool:
    d = _definition()
    return isinstance(t, (d.AbstractString, d.AbstractWString))


# ============================================================================ encode

def _drop_surrogates(s: str) -> str:
    return "".join(c for c in s if not 0xD800 <= ord(c) <= 0xDFFF)


def _encode_scalar(t, value, path: str, out: list[bytes]) -> None:
    d = _definition()
    if isinstance(t, d.BasicType):
        name = t.typename
        if name == "octet":
            return  # byte fields vanish in rmw_desert
        if name == "boolean":
            out.append(cbor_bool(bool(value)))
        elif name in _FLOATS:
            out.append(cbor_float_rmw(float(value)))
        elif name in _INT_RANGES:
            if isinstance(value, str):  # rclpy 'char'/'wchar' may hold a 1-char str
                value = ord(value) if value else 0
            v = int(value)
            lo, hi = _INT_RANGES[name]
            if not lo <= v <= hi:
                raise PeerError(f"{v} is out of range for {name}", path)
            out.append(cbor_int(v))
        else:
            raise PeerError(f"unsupported basic type {name}", path)
    elif isinstance(t, d.AbstractWString):
        out.append(cbor_text(_drop_surrogates(value)))
    elif isinstance(t, d.AbstractString):
        out.append(cbor_text(value))
    elif isinstance(t, d.NamespacedType):
        out.extend(encode_message_items(value, path))
    else:
        raise PeerError(f"unsupported type {t!r}", path)


def encode_message_items(msg, path: str = "") -> list[bytes]:
    """The CBOR items of `msg`'s fields in rmw_desert's form (flattened, in order)."""
    d = _definition()
    members = fields_of(type(msg))
    if not members:
        return [cbor_int(0)]  # rosidl's dummy member of an empty message
    out: list[bytes] = []
    for name, t in members:
        value = getattr(msg, name)
        where = f"{path}.{name}" if path else name
        if isinstance(t, d.AbstractNestedType):
            element = t.value_type
            if _is_octet(element):
                continue  # byte[N], byte[]: nothing, not even the count
            values = list(value)
            if isinstance(t, d.Array):
                if len(values) != t.size:
                    raise PeerError(f"fixed array needs {t.size} elements, has {len(values)}",
                                    where)
                if _is_stringish(element):
                    out.append(cbor_int(len(values)))  # rmw_desert's C path writes it
            else:
                if isinstance(t, d.BoundedSequence) and len(values) > t.maximum_size:
                    raise PeerError(f"{len(values)} elements, bound is {t.maximum_size}", where)
                out.append(cbor_int(len(values)))
            for i, v in enumerate(values):
                _encode_scalar(element, v, f"{where}[{i}]", out)
        else:
            _encode_scalar(t, value, where, out)
    return out


def topic_payload(topic_id: int, msg) -> bytes:
    return cbor_int(KIND_TOPIC) + cbor_int(topic_id) + b"".join(encode_message_items(msg))


def request_payload(service_id: int, seq: int, request) -> bytes:
    return (cbor_int(KIND_REQUEST) + cbor_int(service_id) + cbor_int(seq)
            + b"".join(encode_message_items(request)))


def response_payload(service_id: int, seq: int, response) -> bytes:
    return (cbor_int(KIND_RESPONSE) + cbor_int(service_id) + cbor_int(seq)
            + b"".join(encode_message_items(response)))


# ============================================================================ decode

class _Reader:
    def __init__(self, items: list[Item], start: int):
        self.items = items
        self.pos = start

    def take(self, path: str) -> Item:
        if self.pos >= len(self.items):
            raise PeerError("missing item", path)
        item = self.items[self.pos]
        self.pos += 1
        return item

    def uint(self, path: str) -> int:
        item = self.take(path)
        if item.kind != "uint":
            raise PeerError(f"expected an unsigned integer, got {item.kind}", path)
        return item.value


def _decode_scalar(t, r: _Reader, path: str):
    d = _definition()
    if isinstance(t, d.BasicType):
        name = t.typename
        item = r.take(path)
        if name == "boolean":
            if item.kind != "bool":
                raise PeerError(f"expected F4/F5 for a bool, got {item.kind} {item.value!r}",
                                path)
            return item.value
        if name in _FLOATS:
            if item.kind not in ("half", "single"):
                raise PeerError(f"expected a half or single float, got {item.kind}", path)
            return float(item.value)
        if name in _INT_RANGES:
            if item.kind not in ("uint", "nint"):
                raise PeerError(f"expected an integer, got {item.kind}", path)
            lo, hi = _INT_RANGES[name]
            if not lo <= item.value <= hi:
                raise PeerError(f"{item.value} is out of range for {name}", path)
            return item.value
        raise PeerError(f"unsupported basic type {name}", path)
    if isinstance(t, (d.AbstractString, d.AbstractWString)):
        item = r.take(path)
        if item.kind != "text":
            raise PeerError(f"expected text, got {item.kind}", path)
        if len(item.value.encode("utf-8")) > MAX_TEXT:
            raise PeerError(f"text over {MAX_TEXT} bytes overflows rmw_desert", path)
        bound = getattr(t, "maximum_size", None)
        if bound is not None and len(item.value) > bound:
            raise PeerError(f"string longer than its bound {bound}", path)
        return item.value
    if isinstance(t, d.NamespacedType):
        return _decode_message(_nested_class(t), r, path)
    raise PeerError(f"unsupported type {t!r}", path)


def _decode_message(cls, r: _Reader, path: str):
    d = _definition()
    msg = cls()
    members = fields_of(cls)
    if not members:
        r.uint(path or cls.__name__)
        return msg
    for name, t in members:
        where = f"{path}.{name}" if path else name
        if isinstance(t, d.AbstractNestedType):
            element = t.value_type
            if _is_octet(element):
                continue
            if isinstance(t, d.Array):
                count = t.size
                if _is_stringish(element):
                    got = r.uint(f"{where}.count")
                    if got != t.size:
                        raise PeerError(f"count {got} for a fixed array of {t.size}", where)
            else:
                count = r.uint(f"{where}.count")
                # Refuse a count the payload cannot back before allocating anything.
                need = _min_items(element)
                if need == 0 and count > MAX_ITEMS or (need and count > len(r.items) - r.pos):
                    raise PeerError(f"count {count} exceeds the items left", where)
                if isinstance(t, d.BoundedSequence) and count > t.maximum_size:
                    raise PeerError(f"count {count} exceeds the bound {t.maximum_size}", where)
            values = [_decode_scalar(element, r, f"{where}[{i}]") for i in range(count)]
            setattr(msg, name, values)
        elif not _is_octet(t):  # a scalar byte is not on the wire: keep its default
            setattr(msg, name, _decode_scalar(t, r, where))
    return msg


def split_header(payload: bytes, limits: bool = True
                 ) -> tuple[int, int, int | None, list[Item], int]:
    """(kind, id, seq or None, items, index of the first field item); PeerError if bad.

    Applies rmw_desert's receive limits (512 bytes, 64 items) first; `limits=False`
    lifts them, for tests that compare encodings of types too big for rmw_desert.
    """
    if limits and len(payload) > MAX_RX_PAYLOAD:
        raise PeerError(f"payload of {len(payload)} bytes: rmw_desert drops over {MAX_RX_PAYLOAD}")
    items = read_items(payload)
    if limits and len(items) > MAX_ITEMS:
        raise PeerError(f"{len(items)} items: rmw_desert keeps only {MAX_ITEMS}")
    if len(items) < 2 or items[0].kind != "uint" or items[1].kind != "uint":
        raise PeerError("header: kind and id must be unsigned integers")
    kind, ident = items[0].value, items[1].value
    if kind in (KIND_REQUEST, KIND_RESPONSE):
        if len(items) < 3 or items[2].kind != "uint":
            raise PeerError("header: seq must be an unsigned integer")
        return kind, ident, items[2].value, items, 3
    return kind, ident, None, items, 2


def decode_fields(cls, items: list[Item], start: int):
    """An instance of `cls` from items[start:], which it must consume exactly."""
    r = _Reader(items, start)
    msg = _decode_message(cls, r, "")
    if r.pos != len(items):
        raise PeerError(f"{len(items) - r.pos} item(s) left over after the last field")
    return msg


def decode_topic(payload: bytes, cls, limits: bool = True):
    kind, _, _, items, start = split_header(payload, limits)
    if kind != KIND_TOPIC:
        raise PeerError(f"kind {kind} is not a topic message")
    return decode_fields(cls, items, start)


# ============================================================================ JSON <-> message

def to_plain(msg) -> Any:
    """A JSON-able dict of a message (byte fields as lists of ints)."""
    d = _definition()
    out = {}
    for name, t in fields_of(type(msg)):
        out[name] = _plain_value(getattr(msg, name), t, d)
    return out


def _plain_value(value, t, d):
    if isinstance(t, d.AbstractNestedType):
        return [_plain_value(v, t.value_type, d) for v in value]
    if isinstance(t, d.NamespacedType):
        return to_plain(value)
    if isinstance(value, (bytes, bytearray)):
        return list(value) if len(value) != 1 else value[0]
    if isinstance(value, float) or (hasattr(value, "dtype") and "float" in str(value.dtype)):
        v = float(value)
        return v if math.isfinite(v) else str(v)
    if isinstance(value, bool):
        return value
    if hasattr(value, "__int__") and not isinstance(value, str):
        return int(value)
    return value


def from_plain(cls, data: dict, path: str = ""):
    """An instance of `cls` with the fields given in `data` (others keep defaults)."""
    d = _definition()
    msg = cls()
    members = dict(fields_of(cls))
    for name, value in (data or {}).items():
        where = f"{path}.{name}" if path else name
        if name not in members:
            raise PeerError(f"no such field in {cls.__name__}", where)
        t = members[name]
        if isinstance(t, d.NamespacedType):
            value = from_plain(_nested_class(t), value, where)
        elif isinstance(t, d.AbstractNestedType):
            element = t.value_type
            if isinstance(element, d.NamespacedType):
                value = [from_plain(_nested_class(element), v, f"{where}[{i}]")
                         for i, v in enumerate(value)]
            elif _is_octet(element):
                value = [bytes([v]) for v in value]
        elif _is_octet(t):
            value = bytes([value])
        setattr(msg, name, value)
    return msg


# ============================================================================ frames, beacons

def frame(payload: bytes) -> bytes:
    """`99 99 LEN payload 55`, LEN wrapped modulo 256 as rmw_desert does."""
    return b"\x99\x99" + bytes([len(payload) & 0xFF]) + payload + b"\x55"


class FrameHunter:
    """Finds frames in a byte stream: on any mismatch, drop the first 0x99 and hunt on."""

    def __init__(self):
        self.buf = bytearray()
        self.discarded = 0

    def feed(self, data: bytes) -> list[bytes]:
        self.buf += data
        out = []
        while True:
            start = self.buf.find(b"\x99\x99")
            if start < 0:
                keep = 1 if self.buf[-1:] == b"\x99" else 0
                self.discarded += len(self.buf) - keep
                del self.buf[:len(self.buf) - keep]
                return out
            if start:
                self.discarded += start
                del self.buf[:start]
            if len(self.buf) < 3:
                return out
            length = self.buf[2]
            if len(self.buf) < 4 + length:
                return out
            if length and self.buf[3 + length] == 0x55:
                out.append(bytes(self.buf[3:3 + length]))
                del self.buf[:4 + length]
            else:
                self.discarded += 1
                del self.buf[:1]


def rmw_type(ros_type: str, entity: int) -> str:
    pkg, ns, name = ros_type.split("/")
    if ns == "srv":
        name += "_Response" if entity == SERVICE else "_Request"
    return f"{pkg}__{ns}/{name}"


def beacon_payload(node: str, namespace: str, entity: int, gid: bytes, topic: str,
                   type_name: str, disconnect: bool) -> bytes:
    return (cbor_int(KIND_TOPIC) + cbor_int(DISCOVERY_ID) + cbor_text(node)
            + cbor_text(namespace) + cbor_int(entity) + cbor_int(len(gid))
            + b"".join(cbor_int(b) for b in gid) + cbor_text(topic) + cbor_text(type_name)
            + cbor_bool(disconnect))


def parse_beacon(items: list[Item]) -> dict:
    """The fields of a beacon (items of a kind-0 id-1 payload); PeerError if malformed."""
    r = _Reader(items, 2)

    def text(what):
        item = r.take(what)
        if item.kind != "text":
            raise PeerError(f"expected text, got {item.kind}", what)
        return item.value

    node, namespace = text("node_name"), text("node_namespace")
    entity = r.uint("entity")
    count = r.uint("gid.count")
    if count != 16:
        raise PeerError(f"gid count {count}, expected 16")
    gid = bytes(r.uint(f"gid[{i}]") & 0xFF for i in range(count))
    topic, type_name = text("topic"), text("type_name")
    flag = r.take("disconnect")
    if flag.kind != "bool":
        raise PeerError(f"disconnect: expected F4/F5, got {flag.kind}")
    if r.pos != len(items):
        raise PeerError("items left over after a beacon")
    return {"node": node, "namespace": namespace, "entity": ENTITY_NAMES.get(entity, entity),
            "gid": gid.hex(), "topic": topic, "type": type_name, "disconnect": flag.value}


# ============================================================================ id table

def load_id_table(path: str | None) -> dict[str, int]:
    """rmw_desert's `{"topics": {name: id}}`, from $ROS_ALLOWED_TOPICS_CONFIG or cwd."""
    path = path or os.environ.get("ROS_ALLOWED_TOPICS_CONFIG") or "ros_allowed_topics.conf"
    with open(path, encoding="utf-8") as f:
        table = json.load(f)["topics"]
    return {str(k): int(v) for k, v in table.items()}


# ============================================================================ the process

@dataclass
class Entity:
    kind: int
    name: str
    ros_type: str
    cls: Any
    id: int
    gid: bytes
    data: dict = field(default_factory=dict)


class Peer:
    """One rmw_desert-like node on one DESERT socket (see module doc and --help)."""

    def __init__(self, args, table: dict[str, int]):
        self.args = args
        self.table = table
        self.rng = random.Random(args.seed)
        self.entities: list[Entity] = []
        self.by_id: dict[int, list[Entity]] = {}
        self.sock: socket.socket | None = None
        self.hunter = FrameHunter()
        self.errors = 0
        self.received: dict[str, int] = {}
        self.remote_services: set[str] = set()
        self.remote_subscribers: set[str] = set()
        self.pending: dict[str, dict] = {}      # service -> {"seq", "sent_at"} of a call
        self.calls_done: dict[str, bool] = {}
        self.published: dict[str, int] = {}
        self.next_pub: dict[str, float] = {}
        self.stats = {"frames_in": 0, "frames_out": 0, "ignored_ids": 0, "beacons_heard": 0,
                      "requests_heard": 0, "bytes_discarded": 0}
        for spec, kind in ((args.pub, PUBLISHER), (args.sub, SUBSCRIBER),
                           (args.call, CLIENT), (args.serve, SERVICE)):
            for item in spec:
                self._add(kind, item)

    # --- set-up
    def _add(self, kind: int, spec: str) -> None:
        name, _, ros_type = spec.partition("=")
        if not ros_type:
            raise SystemExit(f"--{ENTITY_NAMES[kind]}: expected NAME=pkg/msg/Type, got {spec!r}")
        if name not in self.table:
            # rmw_desert never sends or receives a name missing from its table.
            self.emit("error", reason=f"{name} is not in the id table; entity ignored")
            self.errors += 1
            return
        cls = import_type(ros_type)
        gid = bytes(self.rng.getrandbits(8) for _ in range(16))
        data = json.loads(self.args.data_map.get(name, "{}"))
        ent = Entity(kind, name, ros_type, cls, self.table[name], gid, data)
        self.entities.append(ent)
        self.by_id.setdefault(ent.id, []).append(ent)

    # --- output
    def emit(self, event: str, **fields) -> None:
        fields = {"event": event, "t": round(time.monotonic() - self.t0, 3)
                  if hasattr(self, "t0") else 0.0, **fields}
        sys.stdout.write(json.dumps(fields, sort_keys=False) + "\n")
        sys.stdout.flush()

    # --- socket
    def connect(self) -> None:
        port = int(self.args.port or os.environ.get("DESERT_PORT", "4000"))
        deadline = time.monotonic() + self.args.connect_timeout
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
                break
            except OSError as exc:
                if time.monotonic() > deadline:
                    raise SystemExit(f"cannot connect to DESERT on 127.0.0.1:{port}: {exc}")
                time.sleep(0.05)
        self.sock.setblocking(False)
        self.emit("connected", port=port)

    def send(self, payload: bytes) -> None:
        data = frame(payload)
        assert self.sock is not None
        self.sock.setblocking(True)
        try:
            self.sock.sendall(data)
        finally:
            self.sock.setblocking(False)
        self.stats["frames_out"] += 1

    # --- discovery
    def beacon(self, ent: Entity, disconnect: bool = False) -> bytes:
        if disconnect:
            return beacon_payload(self.args.node, self.args.namespace, ent.kind, ent.gid,
                                  "", "", True)
        return beacon_payload(self.args.node, self.args.namespace, ent.kind, ent.gid,
                              ent.name, rmw_type(ent.ros_type, ent.kind), False)

    def send_beacons(self) -> None:
        if DISCOVERY_ID not in self.table.values() or self.args.no_beacons:
            return
        for ent in self.entities:
            self.send(self.beacon(ent))

    # --- receive
    def on_payload(self, payload: bytes) -> None:
        try:
            kind, ident, seq, items, start = split_header(payload)
        except PeerError as exc:
            self.errors += 1
            self.emit("error", reason=str(exc), payload=payload.hex())
            return
        if kind not in (KIND_TOPIC, KIND_REQUEST, KIND_RESPONSE):
            self.errors += 1
            self.emit("error", reason=f"kind {kind} would kill an rmw_desert node",
                      payload=payload.hex(), fatal=True)
            return
        if kind == KIND_TOPIC and ident == DISCOVERY_ID and self.table.get("/discovery") == 1:
            try:
                beacon = parse_beacon(items)
            except PeerError as exc:
                self.errors += 1
                self.emit("error", reason=f"beacon: {exc}", payload=payload.hex())
                return
            self.stats["beacons_heard"] += 1
            if beacon["entity"] == "service" and not beacon["disconnect"]:
                self.remote_services.add(beacon["topic"])
            if beacon["entity"] == "subscriber" and not beacon["disconnect"]:
                self.remote_subscribers.add(beacon["topic"])
            self.emit("beacon", **beacon)
            return
        if kind == KIND_TOPIC and ident == DISCOVERY_REQUEST_ID and \
                self.table.get("/discovery_request") == 2:
            self.stats["requests_heard"] += 1
            self.emit("discovery_request")
            self.send_beacons()
            return
        wanted = {KIND_TOPIC: SUBSCRIBER, KIND_REQUEST: SERVICE, KIND_RESPONSE: CLIENT}[kind]
        ent = next((e for e in self.by_id.get(ident, []) if e.kind == wanted), None)
        if ent is None:
            self.stats["ignored_ids"] += 1
            return
        cls = ent.cls
        if kind == KIND_REQUEST:
            cls = ent.cls.Request
        elif kind == KIND_RESPONSE:
            cls = ent.cls.Response
        try:
            msg = decode_fields(cls, items, start)
        except PeerError as exc:
            self.errors += 1
            self.emit("error", reason=f"{ent.name}: {exc}", payload=payload.hex())
            return
        if kind == KIND_TOPIC:
            self.received[ent.name] = self.received.get(ent.name, 0) + 1
            self.emit("message", topic=ent.name, data=to_plain(msg), payload=payload.hex())
        elif kind == KIND_REQUEST:
            self.received[ent.name] = self.received.get(ent.name, 0) + 1
            self.emit("request", service=ent.name, seq=seq, data=to_plain(msg))
            response = from_plain(ent.cls.Response, ent.data)
            self.send(response_payload(ent.id, seq, response))
            self.emit("responded", service=ent.name, seq=seq)
        else:
            call = self.pending.get(ent.name)
            if call is None or call["seq"] != seq:
                self.emit("stray_response", service=ent.name, seq=seq)
                return
            del self.pending[ent.name]
            self.calls_done[ent.name] = True
            self.emit("response", service=ent.name, seq=seq, data=to_plain(msg),
                      elapsed=round(time.monotonic() - call["sent_at"], 3))

    # --- periodic work
    def tick(self, now: float) -> None:
        a = self.args
        for ent in self.entities:
            if ent.kind == PUBLISHER:
                sent = self.published.get(ent.name, 0)
                if a.count and sent >= a.count:
                    continue
                if a.pub_when_subscribed and ent.name not in self.remote_subscribers:
                    continue
                due = self.next_pub.setdefault(ent.name, now + a.pub_delay)
                if now >= due:
                    msg = from_plain(ent.cls, ent.data)
                    payload = topic_payload(ent.id, msg)
                    self.send(payload)
                    self.published[ent.name] = sent + 1
                    self.next_pub[ent.name] = due + 1.0 / a.rate
                    self.emit("published", topic=ent.name, n=sent + 1, payload=payload.hex())
            elif ent.kind == CLIENT and ent.name not in self.calls_done:
                call = self.pending.get(ent.name)
                if call is None:
                    if a.wait_for_service and ent.name not in self.remote_services:
                        continue
                    if now < self.t0 + a.call_delay:
                        continue
                    seq = a.seq if a.seq is not None else self.rng.randrange(0, 1000)
                    request = from_plain(ent.cls.Request, ent.data)
                    self.send(request_payload(ent.id, seq, request))
                    self.pending[ent.name] = {"seq": seq, "sent_at": now}
                    self.emit("called", service=ent.name, seq=seq)
                elif now - call["sent_at"] > a.call_timeout:
                    self.calls_done[ent.name] = False
                    del self.pending[ent.name]
                    self.emit("call_timeout", service=ent.name, seq=call["seq"])

    def done(self) -> bool:
        a = self.args
        for ent in self.entities:
            if ent.kind == PUBLISHER and (not a.count or
                                          self.published.get(ent.name, 0) < a.count):
                return False
            if ent.kind == CLIENT and ent.name not in self.calls_done:
                return False
        return all(self.received.get(name, 0) >= n for name, n in a.expect_map.items())

    def run(self) -> int:
        a = self.args
        self.t0 = time.monotonic()
        self.connect()
        if self.table.get("/discovery_request") == 2 and not a.no_discovery_request:
            self.send(bytes([KIND_TOPIC, DISCOVERY_REQUEST_ID]))
        self.send_beacons()
        self.emit("ready", entities=[{"entity": ENTITY_NAMES[e.kind], "name": e.name,
                                      "id": e.id, "gid": e.gid.hex()} for e in self.entities])
        deadline = self.t0 + a.duration
        closed = False
        while time.monotonic() < deadline:
            now = time.monotonic()
            self.tick(now)
            if a.until_done and self.done():
                break
            readable, _, _ = select.select([self.sock], [], [], 0.01)
            if readable:
                try:
                    data = self.sock.recv(4096)
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if not data:
                    self.emit("disconnected")
                    closed = True
                    break  # rmw_desert connects once and never again
                for payload in self.hunter.feed(data):
                    self.stats["frames_in"] += 1
                    self.on_payload(payload)
        if not closed and not a.no_disconnect and DISCOVERY_ID in self.table.values():
            for ent in self.entities:
                self.send(self.beacon(ent, disconnect=True))
        ok = self.done() and self.errors == 0
        self.stats["bytes_discarded"] = self.hunter.discarded
        self.emit("summary", ok=ok, errors=self.errors, received=self.received,
                  published=self.published, calls={k: v for k, v in self.calls_done.items()},
                  remote_services=sorted(self.remote_services), **self.stats)
        if self.sock is not None:
            # Let DESERT take the last bytes before the socket goes away.
            time.sleep(a.linger)
            self.sock.close()
        return 0 if ok else 1


def _pairs(values: list[str], what: str) -> dict[str, str]:
    out = {}
    for v in values:
        name, sep, rest = v.partition("=")
        if not sep:
            raise SystemExit(f"{what}: expected NAME=VALUE, got {v!r}")
        out[name] = rest
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description="An rmw_desert-like node for tests "
                                            "(JSON lines on stdout).")
    p.add_argument("--node", default="rmw_peer", help="node name in beacons")
    p.add_argument("--namespace", default="/", help="node namespace in beacons")
    p.add_argument("--port", type=int, help="DESERT port (default: $DESERT_PORT or 4000)")
    p.add_argument("--config", help="id table (default: $ROS_ALLOWED_TOPICS_CONFIG or "
                                    "./ros_allowed_topics.conf)")
    p.add_argument("--pub", action="append", default=[], metavar="TOPIC=TYPE")
    p.add_argument("--sub", action="append", default=[], metavar="TOPIC=TYPE")
    p.add_argument("--call", action="append", default=[], metavar="SERVICE=TYPE")
    p.add_argument("--serve", action="append", default=[], metavar="SERVICE=TYPE")
    p.add_argument("--data", action="append", default=[], metavar="NAME=JSON",
                   help="content of what --pub publishes, --call requests or --serve "
                        "answers (fields as JSON; others keep their defaults)")
    p.add_argument("--count", type=int, default=1, help="messages per --pub (0: no end)")
    p.add_argument("--rate", type=float, default=5.0, help="messages per second per --pub")
    p.add_argument("--pub-delay", type=float, default=0.0, help="seconds before the first")
    p.add_argument("--pub-when-subscribed", action="store_true",
                   help="publish only after a subscriber beacon for the topic was heard")
    p.add_argument("--wait-for-service", action="store_true",
                   help="call only after the service's beacon was heard (rmw_desert's "
                        "wait_for_service)")
    p.add_argument("--call-delay", type=float, default=0.0,
                   help="seconds after start before calling")
    p.add_argument("--call-timeout", type=float, default=5.0)
    p.add_argument("--seq", type=int, help="fixed seq for calls (default: random 0..999)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--expect", action="append", default=[], metavar="TOPIC=N",
                   help="done only after N messages arrived on TOPIC (or N requests for a "
                        "--serve SERVICE)")
    p.add_argument("--until-done", action="store_true",
                   help="exit as soon as publishing, calls and --expect are done")
    p.add_argument("--duration", type=float, default=10.0, help="run at most this long")
    p.add_argument("--connect-timeout", type=float, default=5.0)
    p.add_argument("--linger", type=float, default=0.2, help="seconds before closing")
    p.add_argument("--no-discovery-request", action="store_true")
    p.add_argument("--no-beacons", action="store_true")
    p.add_argument("--no-disconnect", action="store_true")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.data_map = _pairs(args.data, "--data")
    args.expect_map = {k: int(v) for k, v in _pairs(args.expect, "--expect").items()}
    table = load_id_table(args.config)
    peer = Peer(args, table)
    try:
        return peer.run()
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
