"""Each feature of the .msg/.srv language parses into the model it means."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from uwgen.idl.model import INTEGER_RANGES, ArrayKind, FieldType, MessageDef, ServiceDef
from uwgen.idl.parser import parse_file, parse_message_string, parse_service_string

PRIMITIVES = ["bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"]


def msg(text: str, package: str = "pkg") -> MessageDef:
    return parse_message_string(text, package, "Msg", "pkg/msg/Msg.msg")


def only_field(text: str):
    (field,) = msg(text).fields
    return field


@pytest.mark.parametrize("base", PRIMITIVES)
def test_every_primitive_is_a_scalar_field_of_that_base(base):
    field = only_field(f"{base} value\n")
    assert field.name == "value"
    assert field.type == FieldType(base)
    assert field.type.is_primitive and not field.type.is_array


def test_char_stays_char_as_rosidl_adapter_reports_it():
    # rosidl_adapter.parser reports `char`; its IDL step maps it to uint8 (what rclpy holds).
    field = only_field("char c 65\n")
    assert field.type.base == "char"
    assert field.default == 65
    assert INTEGER_RANGES["char"] == (0, 255)


@pytest.mark.parametrize(
    "spelling, expected",
    [
        ("string<=8", FieldType("string", string_bound=8)),
        ("wstring<=3", FieldType("wstring", string_bound=3)),
        ("int32[4]", FieldType("int32", ArrayKind.FIXED, 4)),
        ("int32[<=4]", FieldType("int32", ArrayKind.BOUNDED, 4)),
        ("int32[]", FieldType("int32", ArrayKind.UNBOUNDED)),
        ("string<=5[2]", FieldType("string", ArrayKind.FIXED, 2, 5)),
        ("string<=5[<=2]", FieldType("string", ArrayKind.BOUNDED, 2, 5)),
        ("wstring<=5[]", FieldType("wstring", ArrayKind.UNBOUNDED, None, 5)),
        ("Point[3]", FieldType("pkg/msg/Point", ArrayKind.FIXED, 3)),
    ],
)
def test_bounds_and_arrays_are_read_into_the_field_type(spelling, expected):
    field = only_field(f"{spelling} v\n")
    assert field.type == expected
    assert str(field.type) == spelling.replace("Point", "pkg/msg/Point")


@pytest.mark.parametrize(
    "spelling, full",
    [
        ("Point", "pkg/msg/Point"),
        ("geometry_msgs/Point", "geometry_msgs/msg/Point"),
        ("geometry_msgs/msg/Point", "geometry_msgs/msg/Point"),
        ("Header", "pkg/msg/Header"),   # ROS 2 does not special-case a bare Header
    ],
)
def test_nested_type_spellings_are_fully_qualified(spelling, full):
    field = only_field(f"{spelling} p\n")
    assert field.type.base == full
    assert not field.type.is_primitive
    assert msg(f"{spelling} p\n").nested_types() == [full]


@pytest.mark.parametrize(
    "line, name, type_, value",
    [
        ("bool B=true", "B", "bool", True),
        ("bool B=0", "B", "bool", False),
        ("byte B=255", "B", "byte", 255),
        ("char C=0x41", "C", "char", 65),
        ("int8 MIN=-128", "MIN", "int8", -128),
        ("uint64 MAX=18446744073709551615", "MAX", "uint64", 2**64 - 1),
        ("int64 MIN=-9223372036854775808", "MIN", "int64", -(2**63)),
        ("float32 F=1.5", "F", "float32", 1.5),
        ("float64 E=-2e-3", "E", "float64", -0.002),
        ("float64 INF=inf", "INF", "float64", math.inf),
        ("string S=hello world", "S", "string", "hello world"),
        ("string S=\"  padded  \"", "S", "string", "  padded  "),
        ("string S='it\\'s'", "S", "string", "it's"),
        ("string S=\"say \\\"hi\\\"\"", "S", "string", 'say "hi"'),
        ("string S=", "S", "string", ""),
        ("wstring W='ü'", "W", "wstring", "ü"),
        ("int32 SPACED = 7", "SPACED", "int32", 7),
    ],
)
def test_constants_of_every_kind(line, name, type_, value):
    message = msg(line + "\n")
    assert message.fields == []
    (constant,) = message.constants
    assert (constant.name, constant.type, constant.value) == (name, type_, value)
    assert type(constant.value) is type(value)


@pytest.mark.parametrize(
    "line, default",
    [
        ("bool b true", True),
        ("int16 i -1000", -1000),
        ("uint8 u 0b11", 3),
        ("float32 f 1", 1.0),
        ("string s plain words", "plain words"),
        ("string s \"quoted # not\"", '"quoted'),   # '#' starts a comment everywhere, as in ROS
        ("string<=5 s 'abcde'", "abcde"),
        ("int32[3] a [1, -2, 3]", (1, -2, 3)),
        ("float64[<=3] a [1.5,2]", (1.5, 2.0)),
        ("bool[] a []", ()),
        ("uint8[] a [0, 255]", (0, 255)),
        ("string[3] s [\"\", 'b, c', d]", ("", "b, c", "d")),
        ("string[] s [\"x\\\"y\", 'z']", ('x"y', "z")),
        ("string<=2[<=2] s [ab, \"c\"]", ("ab", "c")),
    ],
)
def test_default_values_scalars_and_arrays(line, default):
    field = only_field(line + "\n")
    assert field.default == default
    assert type(field.default) is type(default)


def test_comments_blank_lines_tabs_and_crlf_are_ignored():
    text = (
        "# file comment\r\n"
        "\r\n"
        "int32\tx  # trailing comment\r\n"
        "   # indented comment line\r\n"
        "float64 y\t\t3.5\r\n"
    )
    message = msg(text)
    assert [(f.name, f.type.base, f.default) for f in message.fields] == [("x", "int32", None), ("y", "float64", 3.5)]
    assert [f.where.line for f in message.fields] == [3, 5]


def test_field_locations_are_line_and_column_one():
    message = msg("\n\nint32 a\n# c\nint32 b\nint32 C=1\n")
    assert [(f.where.line, f.where.column) for f in message.fields] == [(3, 1), (5, 1)]
    assert message.constants[0].where.line == 6
    assert str(message.fields[0].where) == "pkg/msg/Msg.msg:3:1"


def test_empty_message_and_constants_only_message():
    assert msg("").fields == [] and msg("").constants == []
    only_constants = msg("uint8 A=1\nuint8 B=2\n")
    assert only_constants.fields == [] and [c.name for c in only_constants.constants] == ["A", "B"]


def test_service_parts_are_named_request_and_response_in_srv_namespace():
    service = parse_service_string("int64 a\nint64 b\n---\nint64 sum\n", "pkg", "AddTwoInts", "pkg/srv/AddTwoInts.srv")
    assert isinstance(service, ServiceDef)
    assert service.full_name == "pkg/srv/AddTwoInts"
    assert service.request.full_name == "pkg/srv/AddTwoInts_Request"
    assert service.response.full_name == "pkg/srv/AddTwoInts_Response"
    assert [f.name for f in service.request.fields] == ["a", "b"]
    assert [(f.name, f.where.line) for f in service.response.fields] == [("sum", 4)]


def test_service_with_empty_request_and_response():
    service = parse_service_string("---\n", "pkg", "Trigger", "Trigger.srv")
    assert service.request.fields == [] and service.response.fields == []


def test_service_nested_types_come_from_the_msg_namespace():
    service = parse_service_string("Point p\n---\n", "pkg", "Go", "Go.srv")
    assert service.request.fields[0].type.base == "pkg/msg/Point"


def test_parse_file_takes_package_and_kind_from_the_path():
    root = Path(__file__).parent / "data" / "broken" / "broken_pkg"
    fine = parse_file(root / "msg" / "Fine.msg")
    assert fine.full_name == "broken_pkg/msg/Fine"
    assert fine.source == root / "msg" / "Fine.msg"
