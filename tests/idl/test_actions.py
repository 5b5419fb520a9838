"""`.action` files: goal, result and feedback parsed as rosidl_adapter does, errors located."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import ActionDef, DefinitionError
from uwgen.idl.parser import parse_action_string, parse_file

from .rosidl_compare import our_shape, ref_shape

rosidl = pytest.importorskip("rosidl_adapter.parser")
INSTALLED = sorted((Path(sys.prefix) / "share").glob("*/action/*.action"))


def test_the_environment_has_actions_to_compare():
    assert any(p.stem == "Fibonacci" for p in INSTALLED)


@pytest.mark.parametrize("path", INSTALLED, ids=lambda p: f"{p.parent.parent.name}/{p.stem}")
def test_action_parser_agrees_with_rosidl_adapter(path: Path):
    package = path.parent.parent.name
    ours = parse_file(path)
    ref = rosidl.parse_action_file(package, str(path))
    assert isinstance(ours, ActionDef) and ours.full_name == f"{package}/action/{path.stem}"
    for mine, theirs in ((ours.goal, ref.goal), (ours.result, ref.result), (ours.feedback, ref.feedback)):
        assert repr(our_shape(mine)) == repr(ref_shape(theirs))
        assert mine.name == theirs.msg_name and mine.namespace == "action"


def test_parts_keep_their_line_numbers():
    action = parse_action_string("int32 order\n---\n# result\nint32[] sequence\n---\nint32 step\n",
                                 "pkg", "Count", "pkg/action/Count.action")
    assert [p.full_name for p in action.parts] == [
        "pkg/action/Count_Goal", "pkg/action/Count_Result", "pkg/action/Count_Feedback"]
    assert [p.fields[0].where.line for p in action.parts] == [1, 4, 6]


@pytest.mark.parametrize("text, where, fragment", [
    ("int32 a\n---\nint32 b\n", "f.action:2:1", "needs two '---' lines"),
    ("int32 a\n", "f.action:1:1", "found 0"),
    ("a\n---\n---\n---\n", "f.action:4:1", "extra '---'"),
    ("int32 a\n--- \n---\n", "f.action:2:1", "exactly '---'"),
    ("int32 a\n---\nint32 b\n---\nint33 c\n", "f.action:5:1", "unknown type 'int33'"),
])
def test_malformed_actions_are_located(text, where, fragment):
    with pytest.raises(DefinitionError) as info:
        parse_action_string(text, "pkg", "Go", "f.action")
    assert str(info.value.where) == where
    assert fragment in info.value.message


def test_library_finds_actions_and_their_parts(tmp_path):
    folder = tmp_path / "nav_msgs2" / "action"
    folder.mkdir(parents=True)
    (folder / "GoTo.action").write_text("geometry_msgs/Point target\n---\nbool ok\n---\nfloat32 left\n")
    lib = InterfaceLibrary([tmp_path])
    assert lib.local_names() == ["nav_msgs2/action/GoTo"]
    assert lib.normalize("nav_msgs2/GoTo") == "nav_msgs2/action/GoTo"
    assert lib.get("nav_msgs2/action/GoTo_Feedback").fields[0].name == "left"
    used = [m.full_name for m in lib.closure(["nav_msgs2/action/GoTo"])]
    assert used[0] == "geometry_msgs/msg/Point" and used[-1] == "nav_msgs2/action/GoTo_Feedback"


def test_library_refuses_an_action_using_a_missing_type(tmp_path):
    folder = tmp_path / "pkg" / "action"
    folder.mkdir(parents=True)
    (folder / "Go.action").write_text("int32 a\n---\npkg/Missing m\n---\n")
    with pytest.raises(DefinitionError) as info:
        InterfaceLibrary([tmp_path], installed=False).get("pkg/action/Go")
    assert str(info.value.where).endswith("Go.action:3:1")
    assert "unknown type 'pkg/msg/Missing'" in info.value.message
