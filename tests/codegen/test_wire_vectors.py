"""Byte-exact vectors for each rule of wire format section 4 (profile native), the
service header of section 5, and the worked examples of section 6."""
from __future__ import annotations

import math

import pytest

from uwgen.codegen import generate
from uwgen.runtime.wire.codec import DecodeError, EncodeError

DEFINITIONS = {
    "vec/msg/B.msg": "bool v",
    "vec/msg/U8.msg": "uint8 v",
    "vec/msg/U16.msg": "uint16 v",
    "vec/msg/U32.msg": "uint32 v",
    "vec/msg/U64.msg": "uint64 v",
    "vec/msg/I8.msg": "int8 v",
    "vec/msg/I64.msg": "int64 v",
    "vec/msg/Ch.msg": "char v",
    "vec/msg/By.msg": "byte v",
    "vec/msg/F32.msg": "float32 v",
    "vec/msg/F64.msg": "float64 v",
    "vec/msg/S.msg": "string v",
    "vec/msg/SB.msg": "string<=3 v",
    "vec/msg/W.msg": "wstring v",
    "vec/msg/Fixed.msg": "int16[3] v",
    "vec/msg/Seq.msg": "int16[] v",
    "vec/msg/BSeq.msg": "int16[<=2] v",
    "vec/msg/Oct.msg": "uint8[] v",
    "vec/msg/OctFixed.msg": "byte[2] v",
    "vec/msg/Nested.msg": "U8 a\nS b",
    "vec/msg/NestSeq.msg": "U8[] v",
    "vec/msg/Nothing.msg": "# no fields\nint32 CONSTANT=5",
    "vec/msg/HasNothing.msg": "Nothing e\nuint8 after",
}


@pytest.fixture(scope="module")
def vec(tmp_path_factory):
    root = tmp_path_factory.mktemp("defs")
    for rel, text in DEFINITIONS.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text + "\n")
    return generate(tmp_path_factory.mktemp("gen"), "uwgen_vec", folders=[root], installed=False)


def enc(vec, name: str, value) -> str:
    codec = vec.codec(f"vec/msg/{name}")
    cls = codec.plain_class()
    return codec.encode(cls(v=value) if value is not None else cls(), [0, 4]).hex(" ").upper()


@pytest.mark.parametrize("name,value,wire", [
    ("B", False, "00 04 00"), ("B", True, "00 04 01"),
    ("U8", 0, "00 04 00"), ("U8", 23, "00 04 17"), ("U8", 24, "00 04 18 18"), ("U8", 255, "00 04 18 FF"),
    ("U16", 256, "00 04 19 01 00"), ("U32", 65536, "00 04 1A 00 01 00 00"),
    ("U64", 2**64 - 1, "00 04 1B FF FF FF FF FF FF FF FF"), ("U64", 2**32, "00 04 1B 00 00 00 01 00 00 00 00"),
    ("I8", -1, "00 04 20"), ("I8", -24, "00 04 37"), ("I8", -25, "00 04 38 18"), ("I8", 127, "00 04 18 7F"),
    ("I64", -2**63, "00 04 3B 7F FF FF FF FF FF FF FF"),
    ("Ch", 65, "00 04 18 41"), ("By", b"\x07", "00 04 07"),
])
def test_integers_use_cbor_shortest_form(vec, name, value, wire):
    assert enc(vec, name, value) == wire


@pytest.mark.parametrize("name,value,wire", [
    ("F32", 1.5, "00 04 F9 3E 00"),           # exact in half
    ("F32", 0.1, "00 04 FA 3D CC CC CD"),     # float32 value rounded, then single
    ("F32", 65504.0, "00 04 F9 7B FF"),       # largest half
    ("F64", 0.5, "00 04 F9 38 00"),
    ("F64", 100000.0, "00 04 FA 47 C3 50 00"),  # exact in single, not half
    ("F64", 1.8, "00 04 FB 3F FC CC CC CC CC CC CD"),
    ("F64", -0.0, "00 04 F9 80 00"),
    ("F64", 5.960464477539063e-08, "00 04 F9 00 01"),  # half subnormal
    ("F64", math.nan, "00 04 F9 7E 00"), ("F64", math.inf, "00 04 F9 7C 00"), ("F64", -math.inf, "00 04 F9 FC 00"),
    ("F32", -math.nan, "00 04 F9 7E 00"),
])
def test_floats_take_the_shortest_exact_width(vec, name, value, wire):
    assert enc(vec, name, value) == wire


def test_text_is_utf8_and_wstring_drops_lone_surrogates(vec):
    assert enc(vec, "S", "hi") == "00 04 62 68 69"
    assert enc(vec, "S", "é") == "00 04 62 C3 A9"
    assert enc(vec, "W", "a\ud800b") == "00 04 62 61 62"
    assert enc(vec, "W", "\ud834\udd1e") == "00 04 64 F0 9D 84 9E"  # a surrogate pair is one code point


def test_arrays_fixed_without_count_sequences_with_count(vec):
    assert enc(vec, "Fixed", [1, -1, 300]) == "00 04 01 20 19 01 2C"
    assert enc(vec, "Seq", [1, 2]) == "00 04 02 01 02"
    assert enc(vec, "Seq", []) == "00 04 00"


def test_octet_arrays_are_one_byte_string(vec):
    assert enc(vec, "Oct", b"\x01\x02\x03") == "00 04 43 01 02 03"
    assert enc(vec, "Oct", [1, 2]) == "00 04 42 01 02"
    assert enc(vec, "OctFixed", [b"\x00", b"\xff"]) == "00 04 42 00 FF"


def test_nested_messages_are_flattened_and_empty_is_one_zero(vec):
    codec = vec.codec("vec/msg/Nested")
    Nested, U8, S = codec.plain_class(), vec.codec("vec/msg/U8").plain_class(), vec.codec("vec/msg/S").plain_class()
    assert codec.encode(Nested(a=U8(v=5), b=S(v="x")), [0, 4]).hex(" ").upper() == "00 04 05 61 78"
    assert enc(vec, "Nothing", None) == "00 04 00"
    has = vec.codec("vec/msg/HasNothing")
    assert has.encode(has.plain_class()(after=7), [0, 4]).hex(" ").upper() == "00 04 00 07"
    seq = vec.codec("vec/msg/NestSeq")
    assert seq.encode(seq.plain_class()(v=[U8(v=1), U8(v=2)]), [0, 4]).hex(" ").upper() == "00 04 02 01 02"


@pytest.mark.parametrize("name,value,path,words", [
    ("U8", 256, "v", "uint8"), ("I8", -129, "v", "int8"), ("U64", -1, "v", "uint64"),
    ("F32", 1e39, "v", "float32"), ("SB", "abcd", "v", "bound of 3"), ("BSeq", [1, 2, 3], "v", "bound of 2"),
    ("Fixed", [1, 2], "v", "fixed array of 3"), ("Seq", [1, 70000], "v[1]", "int16"), ("S", 5, "v", "expected str"),
    ("B", 2, "v", "bool"), ("Oct", [256], "v", "0..255"),
])
def test_encoder_refuses_out_of_bounds_with_the_field_path(vec, name, value, path, words):
    with pytest.raises(EncodeError) as info:
        enc(vec, name, value)
    assert info.value.path == path and words in str(info.value)


def test_encoder_names_the_nested_path_of_a_bad_element(vec):
    seq = vec.codec("vec/msg/NestSeq")
    U8 = vec.codec("vec/msg/U8").plain_class()
    with pytest.raises(EncodeError) as info:
        seq.encode(seq.plain_class()(v=[U8(v=1), U8(v=300)]), [0, 4])
    assert info.value.path == "v[1].v"


@pytest.mark.parametrize("name,wire,path,words", [
    ("U8", "00 04 19 01 00", "v", "uint8"),        # 256 in a uint8
    ("I8", "00 04 38 80", "v", "int8"),            # -129
    ("U8", "00 04 F9 3C 00", "v", "uint8"),        # a float where an int belongs
    ("F64", "00 04 01", "v", "float"),             # an int where a float belongs
    ("B", "00 04 02", "v", "bool"),
    ("U8", "00 04 F5", "v", "uint8"),              # true is not an integer
    ("SB", "00 04 64 61 62 63 64", "v", "bound of 3"),
    ("BSeq", "00 04 03 01 02 03", "v", "bound of 2"),
    ("Seq", "00 04 1A FF FF FF FF 01", "v", "exceeds"),  # a count of 4 billion in 8 bytes
    ("Fixed", "00 04 01 02", "v", "ended"),
    ("S", "00 04 42 68 69", "v", "text string"),   # bytes where text belongs
    ("F32", "00 04 FB 47 EF FF FF E0 00 00 01", "v", "float32"),  # beyond float32's range
    ("Nothing", "00 04 01", "(empty)", "unsigned 0"),
])
def test_decoder_refuses_bad_items_with_the_field_path(vec, name, wire, path, words):
    with pytest.raises(DecodeError) as info:
        vec.codec(f"vec/msg/{name}").decode(bytes.fromhex(wire), (0, 4))
    assert info.value.path == path and words in str(info.value)


@pytest.mark.parametrize("wire,words", [
    ("00 04 05 06", "left over"),          # an item after the last field
    ("00 05 05", "expected 4"),            # another id
    ("02 04 05", "expected 0"),            # a service request where a topic message belongs
    ("00 04 05 FF 06", "break"),           # a stray break code
    ("00", "fewer than"),
    ("00 04 19 01", "CBOR"),               # truncated item
])
def test_decoder_refuses_malformed_payloads(vec, wire, words):
    with pytest.raises(DecodeError) as info:
        vec.codec("vec/msg/U8").decode(bytes.fromhex(wire), (0, 4))
    assert words in str(info.value)


def test_decoders_accept_cbor_booleans_too(vec):
    codec = vec.codec("vec/msg/B")
    assert codec.decode(bytes.fromhex("00 04 F5"), (0, 4), ros=False)[0].v is True
    assert codec.decode(bytes.fromhex("00 04 00"), (0, 4), ros=False)[0].v is False


def test_service_header_carries_the_sequence_number(allcodecs):
    from std_srvs.srv import SetBool
    req = allcodecs.codec("std_srvs/srv/SetBool_Request")
    assert req.encode(SetBool.Request(data=True), [2, 13, 330]).hex(" ").upper() == "02 0D 19 01 4A 01"
    msg, header = req.decode(bytes.fromhex("02 0D 19 01 4A 01"), (2, 13, None))
    assert header == [2, 13, 330] and msg.data is True


def test_twist_examples_of_section_6_in_both_profiles(allcodecs):
    from geometry_msgs.msg import Twist
    t = Twist()
    t.linear.x, t.angular.z = 2.0, 1.8
    native = allcodecs.codec("geometry_msgs/msg/Twist").encode(t, [0, 4])
    rmw = allcodecs.codec("geometry_msgs/msg/Twist", "rmw_desert").encode(t, [0, 4])
    assert native.hex(" ").upper() == ("00 04 F9 40 00 F9 00 00 F9 00 00 F9 00 00 F9 00 00 "
                                       "FB 3F FC CC CC CC CC CC CD")
    assert rmw.hex(" ").upper() == "00 04 F9 40 00 F9 00 00 F9 00 00 F9 00 00 F9 00 00 FA 3F E6 66 66"


def test_rmw_desert_examples_of_section_6(allcodecs):
    from std_msgs.msg import Empty, String
    from std_srvs.srv import SetBool
    rmw = lambda name: allcodecs.codec(name, "rmw_desert")  # noqa: E731
    assert rmw("std_msgs/msg/String").encode(String(data="hi"), [0, 11]).hex(" ") == "00 0b 62 68 69"
    assert rmw("std_msgs/msg/Empty").encode(Empty(), [0, 11]).hex(" ") == "00 0b 00"
    assert rmw("std_srvs/srv/SetBool_Request").encode(SetBool.Request(data=True), [2, 13, 330]).hex(" ") \
        == "02 0d 19 01 4a f5"
    assert rmw("std_srvs/srv/SetBool_Response").encode(
        SetBool.Response(success=True, message="ok"), [3, 13, 330]).hex(" ") == "03 0d 19 01 4a f5 62 6f 6b"


def test_rmw_desert_refuses_text_over_127_bytes_and_payloads_over_255(allcodecs):
    from std_msgs.msg import String
    codec = allcodecs.codec("std_msgs/msg/String", "rmw_desert")
    with pytest.raises(EncodeError, match="127"):
        codec.encode(String(data="é" * 64), [0, 11])
    assert codec.encode(String(data="x" * 127), [0, 11])


def test_ros_decoding_falls_back_to_plain_classes_when_rclpy_has_none(vec):
    codec = vec.codec("vec/msg/U8")
    msg, _ = codec.decode(bytes.fromhex("00 04 05"), (0, 4), ros=True)
    assert type(msg) is codec.plain_class() and msg.v == 5
