"""Beacons and discovery requests are byte-exact to wire-format.md section 6, and decoding is total."""
from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

from uwgen.interop.beacons import (
    Beacon, BeaconError, Entity, decode_beacon, derive_gid, encode_beacon,
    encode_discovery_request, is_discovery_payload, is_discovery_request, rmw_type_name,
    ros_type_name)

CAPTURED = bytes.fromhex(
    "99 99 4C 00 01 67 63 61 70 5F 70 75 62 61 2F 00 10 18 29 18 87 01 18 2C 18 56 18 50 "
    "18 42 18 55 18 AC 18 BF 18 8D 18 6F 18 BF 18 80 18 71 18 8B 68 2F 63 68 61 74 74 65 "
    "72 74 73 74 64 5F 6D 73 67 73 5F 5F 6D 73 67 2F 53 74 72 69 6E 67 F4 55".replace(" ", ""))
CAPTURED_PAYLOAD = CAPTURED[3:-1]
CAPTURED_GID = bytes([0x29, 0x87, 0x01, 0x2C, 0x56, 0x50, 0x42, 0x55, 0xAC, 0xBF, 0x8D, 0x6F,
                      0xBF, 0x80, 0x71, 0x8B])
CHATTER = Beacon("cap_pub", "/", Entity.PUBLISHER, CAPTURED_GID, "/chatter",
                 "std_msgs__msg/String", False)


def test_captured_chatter_beacon_is_produced_exactly_from_its_fields():
    payload = encode_beacon(Beacon("cap_pub", "/", Entity.PUBLISHER, CAPTURED_GID, "/chatter",
                                   rmw_type_name("std_msgs/msg/String", Entity.PUBLISHER)))
    assert payload == CAPTURED_PAYLOAD
    assert len(payload) == CAPTURED[2]


def test_captured_chatter_beacon_decodes_back_to_its_fields():
    assert decode_beacon(CAPTURED_PAYLOAD) == CHATTER


def test_disconnect_beacon_has_empty_names_and_f5():
    gone = CHATTER.gone()
    payload = encode_beacon(gone)
    assert payload.endswith(b"\x60\x60\xf5")  # "", "", true
    assert decode_beacon(payload) == gone
    assert gone.gid == CHATTER.gid and gone.disconnect


def test_discovery_request_is_kind_0_id_2_and_nothing_else():
    assert encode_discovery_request() == b"\x00\x02"
    assert is_discovery_request(b"\x00\x02")
    assert not is_discovery_request(b"\x00\x02\x00")
    assert not is_discovery_request(b"\x00\x01")
    assert is_discovery_payload(b"\x00\x02") and is_discovery_payload(CAPTURED_PAYLOAD)
    assert not is_discovery_payload(b"\x00\x04\xf4")


def test_every_truncation_of_the_capture_is_refused():
    for cut in range(len(CAPTURED_PAYLOAD)):
        with pytest.raises(BeaconError):
            decode_beacon(CAPTURED_PAYLOAD[:cut])


def test_item_left_over_is_refused():
    with pytest.raises(BeaconError, match="left over"):
        decode_beacon(CAPTURED_PAYLOAD + b"\x00")


def test_stray_break_byte_is_refused_not_ignored():
    with pytest.raises(BeaconError, match="break"):
        decode_beacon(CAPTURED_PAYLOAD[:10] + b"\xff" + CAPTURED_PAYLOAD[10:])


def test_bool_is_not_accepted_as_entity_and_int_is_not_text():
    as_bool = CAPTURED_PAYLOAD.replace(b"\x61\x2f\x00\x10", b"\x61\x2f\xf4\x10", 1)
    with pytest.raises(BeaconError, match="entity"):
        decode_beacon(as_bool)
    no_text = b"\x00\x01\x05" + CAPTURED_PAYLOAD[10:]
    with pytest.raises(BeaconError, match="node_name"):
        decode_beacon(no_text)


def test_disconnect_as_integer_is_accepted_like_any_uwgen_bool():
    assert decode_beacon(CAPTURED_PAYLOAD[:-1] + b"\x01").disconnect is True
    with pytest.raises(BeaconError, match="disconnect"):
        decode_beacon(CAPTURED_PAYLOAD[:-1] + b"\x02")


def test_wrong_header_or_gid_count_is_refused():
    with pytest.raises(BeaconError, match="not a beacon"):
        decode_beacon(b"\x00\x04" + CAPTURED_PAYLOAD[2:])
    with pytest.raises(BeaconError, match="gid count"):
        decode_beacon(CAPTURED_PAYLOAD.replace(b"\x00\x10\x18\x29", b"\x00\x0f\x18\x29", 1))
    with pytest.raises(BeaconError, match="gid"):
        decode_beacon(CAPTURED_PAYLOAD.replace(b"\x18\x29", b"\x19\x01\x00", 1))


@given(st.binary(max_size=300))
def test_decoding_is_total(data):
    try:
        beacon = decode_beacon(data)
    except BeaconError:
        return
    assert isinstance(beacon, Beacon) and len(beacon.gid) == 16


@given(st.integers(0, len(CAPTURED_PAYLOAD) - 1), st.integers(0, 255))
def test_decoding_a_corrupted_capture_never_raises_anything_else(index, value):
    data = bytearray(CAPTURED_PAYLOAD)
    data[index] = value
    try:
        assert isinstance(decode_beacon(bytes(data)), Beacon)
    except BeaconError:
        pass


names = st.text(min_size=0, max_size=12)


@given(names, names, st.sampled_from(list(Entity)), st.binary(min_size=16, max_size=16),
       names, names, st.booleans())
def test_encode_decode_round_trip(node, ns, entity, gid, topic, type_name, disconnect):
    beacon = Beacon(node, ns, entity, gid, topic, type_name, disconnect)
    assert decode_beacon(encode_beacon(beacon)) == beacon


def test_encoder_refuses_what_rmw_desert_cannot_receive():
    with pytest.raises(BeaconError, match="127"):
        encode_beacon(Beacon("n", "/", Entity.PUBLISHER, bytes(16), "/" + "a" * 127, "t"))
    with pytest.raises(BeaconError, match="one frame"):
        encode_beacon(Beacon("n" * 120, "/", Entity.PUBLISHER, bytes(16), "/" + "a" * 120, "t"))
    with pytest.raises(BeaconError, match="gid"):
        encode_beacon(Beacon("n", "/", Entity.PUBLISHER, bytes(15), "/t", "t"))
    with pytest.raises(BeaconError, match="entity"):
        encode_beacon(Beacon("n", "/", 7, bytes(16), "/t", "t"))


def test_type_name_spelling_of_messages_and_services():
    assert rmw_type_name("std_msgs/msg/String", Entity.SUBSCRIBER) == "std_msgs__msg/String"
    assert rmw_type_name("std_srvs/srv/SetBool", Entity.SERVICE) == "std_srvs__srv/SetBool_Response"
    assert rmw_type_name("std_srvs/srv/SetBool", Entity.CLIENT) == "std_srvs__srv/SetBool_Request"
    assert ros_type_name("std_srvs__srv/SetBool_Response") == "std_srvs/srv/SetBool"
    assert ros_type_name("std_srvs__srv/SetBool_Request") == "std_srvs/srv/SetBool"
    assert ros_type_name("std_msgs__msg/String") == "std_msgs/msg/String"


@pytest.mark.parametrize("call", [
    lambda: rmw_type_name("std_srvs/srv/SetBool", Entity.PUBLISHER),
    lambda: rmw_type_name("std_msgs/msg/String", Entity.SERVICE),
    lambda: rmw_type_name("std_msgs/String", Entity.PUBLISHER),
    lambda: ros_type_name("std_srvs__srv/SetBool"),
    lambda: ros_type_name("std_msgs/msg/String"),
])
def test_type_name_helpers_refuse_what_they_cannot_spell(call):
    with pytest.raises(ValueError):
        call()


def test_derived_gids_are_stable_and_distinct():
    a = derive_gid("demo", "surface", Entity.PUBLISHER, "/turtle1/cmd_vel")
    assert a == derive_gid("demo", "surface", Entity.PUBLISHER, "/turtle1/cmd_vel")
    assert len(a) == 16
    others = {derive_gid("demo", "vehicle", Entity.PUBLISHER, "/turtle1/cmd_vel"),
              derive_gid("demo", "surface", Entity.SUBSCRIBER, "/turtle1/cmd_vel"),
              derive_gid("other", "surface", Entity.PUBLISHER, "/turtle1/cmd_vel"),
              derive_gid("demo", "surface", Entity.PUBLISHER, "/turtle1/pose")}
    assert a not in others and len(others) == 4
