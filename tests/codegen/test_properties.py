"""Property tests: random values round-trip; random bytes never raise anything but
DecodeError, and never take long."""
from __future__ import annotations

import importlib
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosidl_parser import definition as d

from uwgen.runtime.wire.codec import DecodeError

from .rosvalues import INT_RANGES, normalize

TRICKY = [
    "test_msgs/msg/BasicTypes", "test_msgs/msg/Arrays", "test_msgs/msg/BoundedSequences",
    "test_msgs/msg/UnboundedSequences", "test_msgs/msg/Strings", "test_msgs/msg/WStrings",
    "test_msgs/msg/MultiNested", "test_msgs/msg/Defaults", "sensor_msgs/msg/Imu",
    "nav_msgs/msg/Odometry", "sensor_msgs/msg/PointCloud2", "diagnostic_msgs/msg/DiagnosticArray",
]
# Generation-speed health checks only: large nested types are slow to generate, not wrong.
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
# MultiNested holds 3-element arrays of Arrays, BoundedSequences and UnboundedSequences,
# themselves holding arrays of nested types: an example is hundreds of values, 0.25 s to
# draw even with the shorter deep sequences below. 30 examples still reach every field of
# every nested type many times over; the other types keep 60.
HEAVY = {"test_msgs/msg/MultiNested": 30}


def settings_for(type_name: str) -> settings:
    return settings(SETTINGS, max_examples=HEAVY.get(type_name, SETTINGS.max_examples))


def rclpy_class(type_name: str):
    pkg, ns, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{ns}"), name)


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def strategy_for(t, depth: int = 0):
    """A hypothesis strategy of valid values for one rosidl slot type."""
    if isinstance(t, d.AbstractNestedType):
        elem = strategy_for(t.value_type, depth + 1)
        if isinstance(t, d.Array):
            return st.lists(elem, min_size=t.size, max_size=t.size)
        hi = t.maximum_size if isinstance(t, d.BoundedSequence) else 4
        # shorter the deeper: a nested type's sequences inside arrays of nested types
        # (MultiNested) otherwise draw thousands of values and overrun hypothesis's buffer,
        # so most examples were thrown away (234 drawn for 20 kept, 0.2 s each)
        return st.lists(elem, max_size=min(hi, (6, 4, 2)[min(depth, 2)]))
    if isinstance(t, d.NamespacedType):
        return message_strategy(getattr(importlib.import_module(".".join(t.namespaces)), t.name), depth + 1)
    if isinstance(t, (d.AbstractString, d.AbstractWString)):
        bound = getattr(t, "maximum_size", None)
        alphabet = st.characters(blacklist_categories=("Cs",))  # lone surrogates: see the wstring vectors
        return st.text(alphabet, max_size=min(bound or 12, 12))
    name = t.typename
    if name == "boolean":
        return st.booleans()
    if name == "octet":
        return st.binary(min_size=1, max_size=1)
    if name == "float":
        return st.floats(width=32)
    if name == "double":
        return st.floats()
    lo, hi = INT_RANGES[name]
    return st.integers(lo, hi)


def message_strategy(cls, depth: int = 0):
    fields = {name: strategy_for(t, depth) for (name, _), t in
              zip(cls.get_fields_and_field_types().items(), cls.SLOT_TYPES)}
    return st.builds(lambda **kw: cls(**kw), **fields)


@pytest.mark.parametrize("type_name", TRICKY)
def test_random_values_round_trip(allcodecs, type_name):
    cls = rclpy_class(type_name)
    codec = allcodecs.codec(type_name)

    @settings_for(type_name)
    @given(message_strategy(cls))
    def check(msg):
        payload = codec.encode(msg, [0, 7])
        back, _ = codec.decode(payload, (0, 7))
        assert normalize(back) == normalize(msg)

    check()


@pytest.mark.parametrize("profile", ["native", "rmw_desert"])
@pytest.mark.parametrize("type_name", TRICKY[:8] + ["geometry_msgs/msg/Twist", "std_msgs/msg/Empty"])
def test_random_bytes_raise_only_the_decode_error(allcodecs, type_name, profile):
    if (type_name, profile) not in allcodecs.CODECS:
        pytest.skip(f"{type_name} has no {profile} codec (too large for rmw_desert)")
    codec = allcodecs.codec(type_name, profile)

    @SETTINGS
    @given(st.one_of(st.binary(max_size=300), st.binary(max_size=40).map(lambda b: b"\x00\x07" + b)))
    def check(data):
        try:
            codec.decode(data, (0, 7), ros=False)
        except DecodeError:
            pass

    check()


@pytest.mark.parametrize("type_name", TRICKY)
def test_every_damaged_copy_of_a_valid_payload_decodes_or_raises_the_decode_error(allcodecs, type_name):
    """Truncations and single-byte corruptions of a real payload, exhaustively."""
    from .rosvalues import fill
    codec = allcodecs.codec(type_name)
    payload = codec.encode(fill(rclpy_class(type_name), "max"), [0, 7])[:400]
    damaged = [payload[:k] for k in range(len(payload))]
    damaged += [payload[:k] + bytes([payload[k] ^ 0xFF]) + payload[k + 1:] for k in range(len(payload))]
    outcomes = {"ok": 0, "error": 0}
    for data in damaged:
        try:
            codec.decode(data, (0, 7), ros=False)
            outcomes["ok"] += 1
        except DecodeError:
            outcomes["error"] += 1
    assert outcomes["error"] > 0
