"""The peer's reflective serializer reproduces every byte example of wire-format.md section 6.

These vectors were captured from a real rmw_desert, so a pass here means the peer is a
faithful reference to cross-check uwgen's generated `rmw_desert` codecs against.
"""
from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, strategies as st

import rmw_desert_peer as peer


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


TWIST = h("99 99 16 00 04 F9 40 00 F9 00 00 F9 00 00 F9 00 00 F9 00 00 FA 3F E6 66 66 55")
STRING_HI = h("99 99 05 00 0B 62 68 69 55")
EMPTY = h("99 99 03 00 0B 00 55")
SETBOOL_REQ = h("99 99 06 02 0D 19 01 4A F5 55")
SETBOOL_RESP = h("99 99 09 03 0D 19 01 4A F5 62 6F 6B 55")
CHATTER_BEACON = h(
    "99 99 4C 00 01 67 63 61 70 5F 70 75 62 61 2F 00 10 18 29 18 87 01 18 2C 18 56 18 50 "
    "18 42 18 55 18 AC 18 BF 18 8D 18 6F 18 BF 18 80 18 71 18 8B 68 2F 63 68 61 74 74 65 "
    "72 74 73 74 64 5F 6D 73 67 73 5F 5F 6D 73 67 2F 53 74 72 69 6E 67 F4 55")


def test_twist_matches_rmw_desert_capture():
    from geometry_msgs.msg import Twist
    msg = Twist()
    msg.linear.x = 2.0
    msg.angular.z = 1.8
    assert peer.frame(peer.topic_payload(4, msg)) == TWIST


def test_twist_capture_decodes_back():
    from geometry_msgs.msg import Twist
    msg = peer.decode_topic(TWIST[3:-1], Twist)
    assert msg.linear.x == 2.0
    assert msg.angular.z == pytest.approx(1.8, abs=1e-6)  # float32 precision: documented loss
    assert (msg.linear.y, msg.linear.z, msg.angular.x, msg.angular.y) == (0.0, 0.0, 0.0, 0.0)


def test_string_and_empty_match_capture():
    from std_msgs.msg import Empty, String
    assert peer.frame(peer.topic_payload(11, String(data="hi"))) == STRING_HI
    assert peer.frame(peer.topic_payload(11, Empty())) == EMPTY
    assert peer.decode_topic(STRING_HI[3:-1], String).data == "hi"
    assert isinstance(peer.decode_topic(EMPTY[3:-1], Empty), Empty)


def test_setbool_request_and_response_match_capture():
    from std_srvs.srv import SetBool
    req = SetBool.Request(data=True)
    resp = SetBool.Response(success=True, message="ok")
    assert peer.frame(peer.request_payload(13, 330, req)) == SETBOOL_REQ
    assert peer.frame(peer.response_payload(13, 330, resp)) == SETBOOL_RESP
    kind, ident, seq, items, start = peer.split_header(SETBOOL_RESP[3:-1])
    assert (kind, ident, seq) == (3, 13, 330)
    back = peer.decode_fields(SetBool.Response, items, start)
    assert (back.success, back.message) == (True, "ok")


def test_beacon_matches_capture_and_parses_back():
    payload = CHATTER_BEACON[3:-1]
    fields = peer.parse_beacon(peer.read_items(payload))
    assert fields["node"] == "cap_pub" and fields["topic"] == "/chatter"
    assert fields["type"] == "std_msgs__msg/String" and fields["disconnect"] is False
    rebuilt = peer.beacon_payload("cap_pub", "/", peer.PUBLISHER, bytes.fromhex(fields["gid"]),
                                  "/chatter", peer.rmw_type("std_msgs/msg/String", 0), False)
    assert peer.frame(rebuilt) == CHATTER_BEACON


def test_bool_as_integer_is_refused():
    from std_srvs.srv import SetBool
    native = h("02 0D 19 01 4A 01")  # native-profile bool: rmw_desert misreads it
    _, _, _, items, start = peer.split_header(native)
    with pytest.raises(peer.PeerError, match="data"):
        peer.decode_fields(SetBool.Request, items, start)


def test_double_float_is_refused():
    from std_msgs.msg import Float64
    payload = h("00 05 FB 3F FC CC CC CC CC CC CD")
    with pytest.raises(peer.PeerError, match="double"):
        peer.decode_topic(payload, Float64)


def test_byte_fields_vanish_and_uint8_arrays_go_element_by_element():
    from test_msgs.msg import Arrays
    msg = Arrays()
    msg.byte_values = [b"\x01", b"\x02", b"\x03"]
    msg.char_values = [1, 2, 3]
    items = peer.encode_message_items(msg)
    joined = b"".join(items)
    # first field bool[3] = F4 F4 F4, then byte[3] absent, then char (uint8) [3]: 01 02 03
    assert joined.startswith(h("F4 F4 F4 01 02 03"))
    back = peer.decode_topic(h("00 09") + joined, Arrays, limits=False)
    assert list(back.char_values) == [1, 2, 3]
    assert back.byte_values == [b"\x00"] * 3  # never sent: defaults


def test_fixed_string_array_carries_count_but_numeric_does_not():
    from test_msgs.msg import Arrays
    msg = Arrays()
    msg.string_values = ["a", "", "c"]
    items = peer.encode_message_items(msg)
    joined = b"".join(items)
    assert h("03 61 61 60 61 63") in joined
    back = peer.decode_topic(h("00 09") + joined, Arrays, limits=False)
    assert back.string_values == ["a", "", "c"]


def test_sequences_carry_counts():
    from test_msgs.msg import UnboundedSequences
    msg = UnboundedSequences()
    msg.uint8_values = [7, 200]
    msg.byte_values = [b"\x05"]
    joined = b"".join(peer.encode_message_items(msg))
    # bool[] empty: 00; byte[] absent (count too); char[] empty: 00; float32[]: 00; float64[]: 00;
    # int8[]: 00; uint8[] = 02 07 18 C8
    assert joined.startswith(h("00 00 00 00 00 02 07 18 C8"))


def test_float64_is_narrowed_like_a_c_cast():
    assert peer.cbor_float_rmw(1.5) == h("F9 3E 00")
    assert peer.cbor_float_rmw(math.pi) == b"\xfa" + struct.pack(">f", math.pi)
    assert peer.cbor_float_rmw(1e300) == h("F9 7C 00")  # overflow to +inf
    assert peer.cbor_float_rmw(float("nan")) == h("F9 7E 00")


@given(st.floats(allow_nan=False, width=32))
def test_float_round_trips_exactly_through_float32_forms(x):
    item = peer.read_items(peer.cbor_float_rmw(x))[0]
    assert item.kind in ("half", "single")
    assert item.value == x and math.copysign(1, item.value) == math.copysign(1, x)


@given(st.binary(max_size=80))
def test_reader_is_total(data):
    try:
        peer.read_items(data)
    except peer.PeerError:
        pass


def test_receive_limit_of_64_items():
    from std_msgs.msg import UInt8MultiArray  # data is uint8[]: element by element
    msg = UInt8MultiArray()
    msg.data = list(range(62))
    payload = peer.topic_payload(9, msg)
    with pytest.raises(peer.PeerError, match="64"):
        peer.decode_topic(payload, UInt8MultiArray)


def test_frame_hunter_resyncs_after_garbage_and_wraps_len():
    hunter = peer.FrameHunter()
    good = peer.frame(b"\x00\x0b\x00")
    out = hunter.feed(b"\x99\x99\x05\x00\x01" + b"\x12" + good[:4])
    out += hunter.feed(good[4:])
    assert out == [b"\x00\x0b\x00"]
    assert peer.frame(bytes(300))[2] == 300 % 256
