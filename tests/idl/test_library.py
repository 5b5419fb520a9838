"""InterfaceLibrary finds interfaces in folders and installed packages, lazily, with located errors."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from uwgen.idl.loader import InterfaceLibrary, UnknownInterface
from uwgen.idl.model import DefinitionError, MessageDef, ServiceDef

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"
BROKEN = Path(__file__).parent / "data" / "broken"
BROKEN_PKG = BROKEN / "broken_pkg"


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def lib() -> InterfaceLibrary:
    return InterfaceLibrary(folders=[SAMPLES], installed=True)


def test_samples_define_turtlesim_only(lib):
    assert lib.local_names() == [
        "turtlesim/action/RotateAbsolute", "turtlesim/msg/Color", "turtlesim/msg/Pose",
        "turtlesim/srv/Kill", "turtlesim/srv/SetPen", "turtlesim/srv/Spawn",
        "turtlesim/srv/TeleportAbsolute", "turtlesim/srv/TeleportRelative",
    ]


def test_turtlesim_samples_match_jazzy(lib):
    def shape(m):
        return [(f.name, str(f.type)) for f in m.fields]
    assert shape(lib.get("turtlesim/msg/Pose")) == [
        ("x", "float32"), ("y", "float32"), ("theta", "float32"),
        ("linear_velocity", "float32"), ("angular_velocity", "float32")]
    assert shape(lib.get("turtlesim/msg/Color")) == [("r", "uint8"), ("g", "uint8"), ("b", "uint8")]
    set_pen = lib.get("turtlesim/srv/SetPen")
    assert shape(set_pen.request) == [(n, "uint8") for n in ("r", "g", "b", "width", "off")]
    rotate = lib.get("turtlesim/action/RotateAbsolute")
    assert [shape(p) for p in rotate.parts] == [
        [("theta", "float32")], [("delta", "float32")], [("remaining", "float32")]]
    assert shape(set_pen.response) == []
    spawn = lib.get("turtlesim/srv/Spawn")
    assert shape(spawn.request) == [("x", "float32"), ("y", "float32"), ("theta", "float32"), ("name", "string")]
    assert shape(spawn.response) == [("name", "string")]
    assert shape(lib.get("turtlesim/srv/Kill").request) == [("name", "string")]
    assert shape(lib.get("turtlesim/srv/TeleportAbsolute").request) == [("x", "float32"), ("y", "float32"), ("theta", "float32")]
    assert shape(lib.get("turtlesim/srv/TeleportRelative").request) == [("linear", "float32"), ("angular", "float32")]


def test_installed_interfaces_are_found_by_every_spelling(lib):
    twist = lib.get("geometry_msgs/msg/Twist")
    assert isinstance(twist, MessageDef) and twist.full_name == "geometry_msgs/msg/Twist"
    assert lib.get("geometry_msgs/Twist") is twist
    set_bool = lib.get("std_srvs/srv/SetBool")
    assert isinstance(set_bool, ServiceDef)
    assert lib.get("std_srvs/SetBool") is set_bool
    assert lib.get("std_srvs/srv/SetBool_Request") is set_bool.request
    assert lib.get("std_srvs/srv/SetBool_Response") is set_bool.response
    assert lib.normalize("std_srvs/SetBool") == "std_srvs/srv/SetBool"
    assert lib.normalize("geometry_msgs/Twist") == "geometry_msgs/msg/Twist"
    assert str(lib.source_of("geometry_msgs/Twist")).endswith("share/geometry_msgs/msg/Twist.msg")


def test_all_names_covers_folders_and_every_installed_file(lib):
    share = Path(sys.prefix) / "share"
    installed = {f"{p.parent.parent.name}/{p.parent.name}/{p.stem}"
                 for p in [*share.glob("*/msg/*.msg"), *share.glob("*/srv/*.srv")]}
    names = set(lib.all_names())
    assert installed <= names
    assert set(lib.local_names()) <= names
    assert lib.all_names() == sorted(names)


def test_find_returns_none_and_get_raises_for_unknown_names(lib):
    assert lib.find("nope_msgs/msg/Nothing") is None
    assert "nope_msgs/Nothing" not in lib
    with pytest.raises(UnknownInterface) as info:
        lib.get("nope_msgs/msg/Nothing")
    assert isinstance(info.value, DefinitionError) and isinstance(info.value, KeyError)
    assert "unknown interface 'nope_msgs/msg/Nothing'" in str(info.value)
    assert str(SAMPLES) in str(info.value) and "share" in str(info.value)


def test_closure_lists_dependencies_first_each_once(lib):
    names = [m.full_name for m in lib.closure(["nav_msgs/msg/Odometry", "geometry_msgs/msg/Twist"])]
    assert len(names) == len(set(names))
    assert names.index("builtin_interfaces/msg/Time") < names.index("std_msgs/msg/Header") < names.index("nav_msgs/msg/Odometry")
    assert names.index("geometry_msgs/msg/Vector3") < names.index("geometry_msgs/msg/Twist")
    assert names[-1] == "nav_msgs/msg/Odometry" or names[-1] == "geometry_msgs/msg/Twist"
    for position, name in enumerate(names):
        for dependency in lib.get(name).nested_types():
            assert names.index(dependency) < position


def test_closure_of_a_service_contributes_request_and_response(lib):
    names = [m.full_name for m in lib.closure(["turtlesim/srv/Spawn", "std_srvs/SetBool"])]
    assert names == ["turtlesim/srv/Spawn_Request", "turtlesim/srv/Spawn_Response",
                     "std_srvs/srv/SetBool_Request", "std_srvs/srv/SetBool_Response"]


def test_closure_of_everything_installed_resolves(lib):
    messages = lib.closure(lib.all_names())
    full = {m.full_name for m in messages}
    assert "test_msgs/msg/MultiNested" in full and "test_msgs/srv/Arrays_Request" in full


def test_a_package_folder_itself_can_be_given():
    lib = InterfaceLibrary(folders=[SAMPLES / "turtlesim"], installed=False)
    assert "turtlesim/msg/Pose" in lib.local_names()
    assert lib.all_names() == lib.local_names()


def test_the_same_folder_given_twice_is_read_once():
    lib = InterfaceLibrary(folders=[SAMPLES, SAMPLES / "turtlesim"], installed=False)
    assert len(lib.local_names()) == 8


def test_installed_false_sees_only_folders():
    lib = InterfaceLibrary(folders=[SAMPLES], installed=False)
    assert lib.find("geometry_msgs/msg/Twist") is None
    assert lib.search_paths() == [SAMPLES]


def test_given_folders_override_an_installed_package_entirely(tmp_path):
    write(tmp_path / "std_msgs" / "msg" / "String.msg", "string data\nuint8 level\n")
    lib = InterfaceLibrary(folders=[tmp_path])
    assert [f.name for f in lib.get("std_msgs/msg/String").fields] == ["data", "level"]
    assert lib.find("std_msgs/msg/Bool") is None   # the installed package is hidden, not mixed in
    assert lib.local_names() == ["std_msgs/msg/String"]


def test_ament_prefix_path_packages_are_found(tmp_path, monkeypatch):
    prefix = tmp_path / "overlay"
    write(prefix / "share" / "sonar_msgs" / "msg" / "Ping.msg", "builtin_interfaces/Time stamp\nfloat32 range\n")
    write(prefix / "share" / "sonar_msgs" / "action" / "Scan.action", "int32 a\n---\n---\n")
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{tmp_path / 'missing'}:{prefix}")
    lib = InterfaceLibrary()
    ping = lib.get("sonar_msgs/Ping")
    assert ping.nested_types() == ["builtin_interfaces/msg/Time"]
    assert prefix / "share" in lib.search_paths()
    assert [n for n in lib.all_names() if n.startswith("sonar_msgs/")] == [
        "sonar_msgs/action/Scan", "sonar_msgs/msg/Ping"]
    scan = lib.get("sonar_msgs/action/Scan")
    assert [p.full_name for p in scan.parts] == [
        "sonar_msgs/action/Scan_Goal", "sonar_msgs/action/Scan_Result", "sonar_msgs/action/Scan_Feedback"]


def test_first_prefix_providing_a_package_wins(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    write(first / "share" / "demo_msgs" / "msg" / "Thing.msg", "int32 first\n")
    write(second / "share" / "demo_msgs" / "msg" / "Thing.msg", "int32 second\n")
    write(second / "share" / "demo_msgs" / "msg" / "Other.msg", "int32 other\n")
    lib = InterfaceLibrary(prefixes=[first, second])
    assert [f.name for f in lib.get("demo_msgs/msg/Thing").fields] == ["first"]
    assert lib.find("demo_msgs/msg/Other") is None


def test_parsing_is_lazy_and_cached():
    # broken_pkg holds broken files; listing them and using a good one must not parse the rest.
    lib = InterfaceLibrary(folders=[BROKEN], installed=False)
    assert "broken_pkg/msg/UsesMissing" in lib.local_names()
    fine = lib.get("broken_pkg/msg/Fine")
    assert lib.get("broken_pkg/Fine") is fine
    with pytest.raises(DefinitionError):
        lib.get("broken_pkg/msg/BadDefault")


def test_unresolvable_nested_type_is_an_error_at_the_field():
    lib = InterfaceLibrary(folders=[BROKEN], installed=False)
    with pytest.raises(DefinitionError) as info:
        lib.get("broken_pkg/msg/UsesMissing")
    assert str(info.value.where) == f"{BROKEN_PKG / 'msg' / 'UsesMissing.msg'}:3:1"
    assert "unknown type 'foo_msgs/msg/Missing' used by broken_pkg/msg/UsesMissing" in info.value.message
    assert f"looked in: {BROKEN}" in info.value.message


def test_bare_header_error_hints_at_std_msgs():
    lib = InterfaceLibrary(folders=[BROKEN])
    with pytest.raises(DefinitionError) as info:
        lib.get("broken_pkg/msg/UsesHeader")
    assert str(info.value.where) == f"{BROKEN_PKG / 'msg' / 'UsesHeader.msg'}:2:1"
    assert "unknown type 'broken_pkg/msg/Header'" in info.value.message
    assert "write std_msgs/Header" in info.value.message


def test_a_service_used_as_a_field_type_is_an_error():
    lib = InterfaceLibrary(folders=[BROKEN])
    with pytest.raises(DefinitionError) as info:
        lib.get("broken_pkg/msg/UsesService")
    assert str(info.value.where) == f"{BROKEN_PKG / 'msg' / 'UsesService.msg'}:1:1"
    assert "'std_srvs/srv/SetBool' is a service; a field needs a message type" in info.value.message


def test_recursive_types_are_refused_where_the_loop_closes():
    lib = InterfaceLibrary(folders=[BROKEN], installed=False)
    with pytest.raises(DefinitionError) as info:
        lib.closure(["broken_pkg/msg/Forward"])
    assert str(info.value.where) == f"{BROKEN_PKG / 'msg' / 'Back.msg'}:2:1"
    assert "broken_pkg/msg/Forward -> broken_pkg/msg/Back -> broken_pkg/msg/Forward" in info.value.message


def test_missing_or_empty_folders_are_errors(tmp_path):
    with pytest.raises(DefinitionError, match="does not exist"):
        InterfaceLibrary(folders=[tmp_path / "nowhere"])
    with pytest.raises(DefinitionError, match="no interfaces found"):
        InterfaceLibrary(folders=[tmp_path])


def test_an_interface_defined_in_two_folders_is_an_error(tmp_path):
    write(tmp_path / "one" / "dup_msgs" / "msg" / "Same.msg", "int32 a\n")
    second = write(tmp_path / "two" / "dup_msgs" / "msg" / "Same.msg", "int32 b\n")
    with pytest.raises(DefinitionError) as info:
        InterfaceLibrary(folders=[tmp_path / "one", tmp_path / "two"], installed=False)
    assert str(info.value.where) == f"{second}:1:1"
    assert "dup_msgs/msg/Same is defined twice" in info.value.message


def test_invalid_package_folder_name_is_an_error(tmp_path):
    write(tmp_path / "Bad-Pkg" / "msg" / "Thing.msg", "int32 a\n")
    with pytest.raises(DefinitionError, match="'Bad-Pkg' is not a valid ROS package name"):
        InterfaceLibrary(folders=[tmp_path], installed=False)
