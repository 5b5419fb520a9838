"""Every mistake in a definition is a DefinitionError at its exact file:line:column."""
from __future__ import annotations

from pathlib import Path

import pytest

from uwgen.idl.model import DefinitionError
from uwgen.idl.parser import parse_file, parse_message_string, parse_service_string

DATA = Path(__file__).parent / "data" / "broken" / "broken_pkg"
MSG = "pkg/msg/Msg.msg"


def msg_error(text: str) -> DefinitionError:
    with pytest.raises(DefinitionError) as info:
        parse_message_string(text, "pkg", "Msg", MSG)
    return info.value


CASES = [
    # (definition, line:column, what the message must say)
    ("int33 x", "1:1", "unknown type 'int33'"),
    ("a/b/c/D x", "1:1", "unknown type 'a/b/c/D'"),
    ("Pkg/Foo f", "1:1", "'Pkg' in type 'Pkg/Foo' is not a valid package name"),
    ("pkg/foo f", "1:5", "'foo' in type 'pkg/foo' is not a valid message name"),
    ("pkg/srv/Foo f", "1:5", "only message types ('pkg/msg/Name') can be fields"),
    ("time stamp", "1:1", "'time' is a ROS 1 type; in ROS 2 use builtin_interfaces/Time"),
    ("int32 x\nint32 Bad", "2:7", "'Bad' is not a valid field name"),
    ("int32 a__b", "1:7", "'a__b' is not a valid field name"),
    ("int32 x\n# gap\nint32 x", "3:7", "duplicate field 'x' (first defined at line 1)"),
    ("uint8 A=1\nuint8 A=2", "2:7", "duplicate constant 'A' (first defined at line 1)"),
    ("int32 lower=1", "1:7", "'lower' is not a valid constant name"),
    ("int32[] X=1", "1:1", "constants must be a primitive type"),
    ("string<=3 X=a", "1:1", "constants must be a primitive type"),
    ("string<=0 s", "1:9", "string bound in 'string<=0' must be > 0"),
    ("string<=x s", "1:9", "string bound in 'string<=x' must be a positive integer, got 'x'"),
    ("int32[0] a", "1:7", "array size in 'int32[0]' must be > 0"),
    ("int32[<=0] a", "1:9", "array bound in 'int32[<=0]' must be > 0"),
    ("int32[-1] a", "1:7", "must be a positive integer, got '-1'"),
    ("int32<=3 a", "1:1", "only string and wstring can have a '<=' bound, not 'int32'"),
    ("int32[3 a", "1:6", "malformed array type 'int32[3'"),
    ("int32] a", "1:6", "']' without '['"),
    ("int32[2][3] a", "1:6", "arrays of arrays are not supported"),
    ("uint8 u 256", "1:9", "256 is out of range for uint8 (0..255)"),
    ("int8 i -129", "1:8", "-129 is out of range for int8 (-128..127)"),
    ("uint16 u -1", "1:10", "-1 is out of range for uint16"),
    ("uint64 u 18446744073709551616", "1:10", "out of range for uint64"),
    ("float32 f 1e39", "1:11", "out of range for float32"),
    ("float64 f 1e999", "1:11", "out of range for float64"),
    ("bool b yes", "1:8", "'yes' is not a bool"),
    ("int32 i 1.5", "1:9", "'1.5' is not an integer"),
    ("float64 f 1,5", "1:11", "'1,5' is not a floating point number"),
    ("int8 X=128", "1:8", "bad value for constant 'X': 128 is out of range for int8"),
    ("char C=256", "1:8", "256 is out of range for char (0..255)"),
    ("geometry_msgs/Point p 1", "1:23", "cannot have a default value"),
    ("string<=3 s abcd", "1:13", "string of 4 characters exceeds the bound string<=3"),
    ('string s "a"b"', "1:12", 'unescaped " inside a "-quoted string'),
    ("int32[3] a [1, 2]", "1:12", "needs exactly 3 elements, got 2"),
    ("int32[<=1] a [1, 2]", "1:14", "allows at most 1 elements, got 2"),
    ("int32[] a [1, x]", "1:15", "element 1: 'x' is not an integer"),
    ("int32[] a [1,,2]", "1:14", "element 1 is empty"),
    ("int32[] a 1", "1:11", "an array default must be written [a, b, ...]"),
    ('string[] s ["a", "b", ]', "1:21", "trailing ','"),  # at the comma
    ('string[] s ["a" "b"]', "1:17", "expected ',' between array elements"),
    ('string[] s ["open]', "1:13", "unterminated \"-quoted string"),
    ("string<=1[] s [a, bc]", "1:19", "element 1: string of 2 characters exceeds the bound"),
    (" int32 x", "1:1", "unexpected indentation"),
    ("int32", "1:6", "expected 'TYPE NAME'"),
    ("int32 a\n---\nint32 b", "2:1", "not allowed in a .msg file"),
]


@pytest.mark.parametrize("text, where, fragment", CASES, ids=[c[0] for c in CASES])
def test_definition_error_is_located_and_explained(text, where, fragment):
    error = msg_error(text + "\n")
    assert str(error.where) == f"{MSG}:{where}"
    assert fragment in error.message
    assert str(error) == f"{MSG}:{where}: {error.message}"


def test_service_without_separator_is_an_error_at_the_start():
    path = DATA / "srv" / "NoSeparator.srv"
    with pytest.raises(DefinitionError) as info:
        parse_file(path)
    assert str(info.value) == f"{path}:1:1: missing '---' between the request and the response of a service"


def test_service_with_two_separators_points_at_the_second():
    path = DATA / "srv" / "TwoSeparators.srv"
    with pytest.raises(DefinitionError) as info:
        parse_file(path)
    assert str(info.value.where) == f"{path}:4:1"
    assert "extra '---'" in info.value.message and "line 2" in info.value.message


def test_separator_with_trailing_space_is_pointed_at():
    with pytest.raises(DefinitionError) as info:
        parse_service_string("int32 a\n--- \nint32 b\n", "pkg", "Srv", "Srv.srv")
    assert str(info.value.where) == "Srv.srv:2:1"
    assert "exactly '---'" in info.value.message


def test_errors_in_a_response_keep_their_file_line_numbers():
    with pytest.raises(DefinitionError) as info:
        parse_service_string("int32 a\n---\n\nint32 Bad\n", "pkg", "Srv", "Srv.srv")
    assert str(info.value.where) == "Srv.srv:4:7"


def test_out_of_range_default_in_a_file():
    path = DATA / "msg" / "BadDefault.msg"
    with pytest.raises(DefinitionError) as info:
        parse_file(path)
    assert str(info.value) == f"{path}:2:13: bad default for field 'level': 300 is out of range for uint8 (0..255)"


def test_invalid_utf8_is_located(tmp_path):
    path = tmp_path / "pkg" / "msg" / "Bin.msg"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"int32 a\nstring s \xff\n")
    with pytest.raises(DefinitionError) as info:
        parse_file(path)
    assert str(info.value.where) == f"{path}:2:10"
    assert "not valid UTF-8" in info.value.message


@pytest.mark.parametrize("package, name, fragment", [
    ("pkg", "bad_name", "'bad_name' is not a valid interface name"),
    ("Pkg", "Good", "'Pkg' is not a valid package name"),
])
def test_invalid_interface_and_package_names(package, name, fragment):
    with pytest.raises(DefinitionError) as info:
        parse_message_string("int32 a\n", package, name, "f.msg")
    assert str(info.value.where) == "f.msg:1:1"
    assert fragment in info.value.message


def test_unknown_file_kind(tmp_path):
    path = tmp_path / "pkg" / "idl" / "Go.idl"
    path.parent.mkdir(parents=True)
    path.write_text("module pkg {};\n")
    with pytest.raises(DefinitionError, match="expected .msg, .srv or .action"):
        parse_file(path)


@pytest.mark.parametrize("separator, column", [("----", 1), ("--", 1), ("  ---", 3), ("- - -", 1),
                                               ("---#", 1), ("—", 1)])
def test_a_bad_service_separator_is_reported_at_its_own_line_and_column(separator, column):
    with pytest.raises(DefinitionError) as info:
        parse_service_string(f"# request\nint32 a\n{separator}\nint32 b\n", "pkg", "Srv", "Srv.srv")
    assert str(info.value.where) == f"Srv.srv:3:{column}"
    assert "exactly '---'" in info.value.message and repr(separator.strip()) in info.value.message


def test_a_bad_action_separator_is_reported_at_its_own_line():
    from uwgen.idl.parser import parse_action_string
    with pytest.raises(DefinitionError) as info:
        parse_action_string("int32 goal\n---\nint32 result\n----\nint32 feedback\n", "pkg", "Act", "Act.action")
    assert str(info.value.where) == "Act.action:4:1"
