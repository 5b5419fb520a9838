"""Profile `packed` on its own (no field encodings): every field of the tricky types
round-trips through ONE byte string after the header, and decoders stay total."""
from __future__ import annotations

import cbor2
import pytest
from hypothesis import given
from hypothesis import strategies as st

from uwgen.codegen import generate
from uwgen.runtime.wire.codec import DecodeError

from .rosvalues import fill, normalize
from .test_properties import SETTINGS, TRICKY, message_strategy, rclpy_class, settings_for

TYPES = TRICKY + ["geometry_msgs/msg/Twist", "std_msgs/msg/Empty", "sensor_msgs/msg/NavSatFix",
                  "sensor_msgs/msg/BatteryState"]


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("packed"), "uwgen_packed_only", names=TYPES,
                    profiles=("native", "packed"))


@pytest.mark.parametrize("type_name", TYPES)
def test_random_values_round_trip_in_packed(packed, type_name):
    cls = rclpy_class(type_name)
    codec = packed.codec(type_name, "packed")

    @settings_for(type_name)
    @given(message_strategy(cls))
    def check(msg):
        payload = codec.encode(msg, [0, 7])
        back, _ = codec.decode(payload, (0, 7))
        assert normalize(back) == normalize(msg)

    check()


@pytest.mark.parametrize("type_name", TYPES)
def test_packed_payload_is_the_header_then_one_byte_string(packed, type_name):
    msg = fill(rclpy_class(type_name), "max")
    payload = packed.codec(type_name, "packed").encode(msg, [0, 7])
    items = cbor2.loads(b"\x9f" + payload + b"\xff")
    assert items[:2] == [0, 7] and len(items) == 3 and type(items[2]) is bytes


def test_packed_is_never_larger_than_native_for_filled_messages(packed):
    for type_name in TYPES:
        msg = fill(rclpy_class(type_name), "max")
        native = packed.codec(type_name, "native").encode(msg, [0, 7])
        pk = packed.codec(type_name, "packed").encode(msg, [0, 7])
        assert len(pk) <= len(native) + 3, type_name   # + the byte string head, at most


@pytest.mark.parametrize("type_name", TYPES)
def test_random_bytes_raise_only_the_decode_error_in_packed(packed, type_name):
    codec = packed.codec(type_name, "packed")

    @SETTINGS
    @given(st.one_of(st.binary(max_size=300),
                     st.binary(max_size=60).map(lambda b: b"\x00\x07" + cbor2.dumps(b))))
    def check(data):
        try:
            codec.decode(data, (0, 7), ros=False)
        except DecodeError:
            pass

    check()


@pytest.mark.parametrize("type_name", TYPES)
def test_every_damaged_packed_payload_decodes_or_raises_the_decode_error(packed, type_name):
    codec = packed.codec(type_name, "packed")
    full = codec.encode(fill(rclpy_class(type_name), "max"), [0, 7])
    bits = cbor2.loads(b"\x9f" + full + b"\xff")[2][:200]
    payload = full[:200]
    damaged = [payload[:k] for k in range(len(payload))]
    damaged += [payload[:k] + bytes([payload[k] ^ 0xFF]) + payload[k + 1:] for k in range(len(payload))]
    damaged += [b"\x00\x07" + cbor2.dumps(bits[:k]) for k in range(len(bits))]
    damaged += [b"\x00\x07" + cbor2.dumps(bits + b"\x00")]
    errors = 0
    for data in damaged:
        try:
            codec.decode(data, (0, 7), ros=False)
        except DecodeError:
            errors += 1
    assert errors > 0


def test_truncated_bits_name_the_field(packed):
    codec = packed.codec("sensor_msgs/msg/NavSatFix", "packed")
    with pytest.raises(DecodeError) as info:
        codec.decode(b"\x00\x07" + cbor2.dumps(b"\x00\x00\x00\x00\x00"), (0, 7), ros=False)
    assert info.value.path.startswith("header.")


def test_leftover_bits_are_refused(packed):
    codec = packed.codec("geometry_msgs/msg/Twist", "packed")
    payload = codec.encode(rclpy_class("geometry_msgs/msg/Twist")(), [0, 7])
    bits = cbor2.loads(b"\x9f" + payload + b"\xff")[2]
    with pytest.raises(DecodeError, match="bits left after the last field"):
        codec.decode(b"\x00\x07" + cbor2.dumps(bits + b"\x00"), (0, 7))


# --- every installed interface, boundary values, profile packed ---------------------------

from .test_roundtrip_installed import MESSAGES, SERVICES, assert_round_trip  # noqa: E402
from .rosvalues import VARIANTS  # noqa: E402


@pytest.fixture(scope="module")
def allpacked(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("allpk"), "uwgen_all_packed", all_installed=True, profiles=("packed",))


def test_every_installed_interface_has_a_packed_codec(allpacked):
    built = {name for name, profile in allpacked.CODECS if profile == "packed"}
    expected = set(MESSAGES) | {f"{s}_{part}" for s in SERVICES for part in ("Request", "Response")}
    assert expected <= built


@pytest.mark.parametrize("type_name", MESSAGES)
def test_every_installed_message_round_trips_packed_with_boundary_values(allpacked, type_name):
    cls = rclpy_class(type_name)
    for variant in VARIANTS:
        assert_round_trip(allpacked.codec(type_name, "packed"), fill(cls, variant), (0, 42))


@pytest.mark.parametrize("type_name", SERVICES)
def test_every_installed_service_round_trips_packed_with_boundary_values(allpacked, type_name):
    import importlib
    pkg, _ns, name = type_name.split("/")
    srv = getattr(importlib.import_module(f"{pkg}.srv"), name)
    for variant in VARIANTS:
        assert_round_trip(allpacked.codec(type_name + "_Request", "packed"), fill(srv.Request, variant), (2, 9, 330))
        assert_round_trip(allpacked.codec(type_name + "_Response", "packed"), fill(srv.Response, variant),
                          (3, 9, 2**64 - 1))
