"""uwgen.typesupport: where builds of your own interfaces live and how bridges find them."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from uwgen import typesupport
from uwgen.typesupport import (
    BuildError, activate_recorded, build_digest, build_dir, cache_root, source_digest,
)

ROOT = Path(__file__).resolve().parents[2]


def test_cache_is_outside_the_source_tree_and_overridable(monkeypatch, tmp_path):
    monkeypatch.delenv("UWGEN_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "uwgen"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_root() == tmp_path / "home" / ".cache" / "uwgen"
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"
    assert ROOT not in build_dir("turtlesim", "0" * 16).parents


def test_digest_follows_the_files_contents(tmp_path):
    pkg = tmp_path / "auv_msgs"
    (pkg / "msg").mkdir(parents=True)
    (pkg / "msg" / "Status.msg").write_text("float32 depth\n")
    first = source_digest(pkg)
    assert source_digest(pkg) == first
    (pkg / "msg" / "Status.msg").write_text("float64 depth\n")
    assert source_digest(pkg) != first


def test_generated_package_records_the_digest_of_its_own_interfaces():
    from uwgen.bridge.plan import import_package
    uwgen_demo = import_package("uwgen_demo", ROOT / "generated")
    label, digest = uwgen_demo.ROS_INTERFACES["turtlesim"]
    assert label == "msg_samples/turtlesim"
    assert digest == build_digest(ROOT / "msg_samples" / "turtlesim")
    assert "geometry_msgs" not in uwgen_demo.ROS_INTERFACES   # installed: nothing to build


def test_a_missing_build_names_the_command_that_makes_it(monkeypatch, tmp_path):
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path))
    with pytest.raises(BuildError, match=r"no type support for nosuch_msgs .*"
                                         r"run `uwgen ros-interfaces interfaces/nosuch_msgs`"):
        activate_recorded({"nosuch_msgs": ("interfaces/nosuch_msgs", "0123456789abcdef")})
    # A build of other files of the package is not taken for this one.
    other = typesupport.build_dir("nosuch_msgs", "fedcba9876543210")
    other.mkdir(parents=True)
    (other / "stamp").write_text("x\n")
    with pytest.raises(BuildError, match="other versions of its files"):
        activate_recorded({"nosuch_msgs": ("interfaces/nosuch_msgs", "0123456789abcdef")})


def test_installed_packages_need_no_build(monkeypatch, tmp_path):
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path))
    assert activate_recorded({"geometry_msgs": ("x/geometry_msgs", "0" * 16)}) == []


def two_packages(root: Path, depth_type: str = "float32") -> Path:
    """interfaces/{ts_base_msgs, ts_report_msgs}: the second uses the first."""
    (root / "ts_base_msgs" / "msg").mkdir(parents=True, exist_ok=True)
    (root / "ts_base_msgs" / "msg" / "Depth.msg").write_text(f"{depth_type} metres\n")
    (root / "ts_report_msgs" / "msg").mkdir(parents=True, exist_ok=True)
    (root / "ts_report_msgs" / "msg" / "Report.msg").write_text("ts_base_msgs/Depth depth\nstring note\n")
    return root


def test_a_package_using_another_of_yours_is_keyed_by_both(tmp_path):
    root = two_packages(tmp_path / "interfaces")
    before, own = build_digest(root / "ts_report_msgs"), source_digest(root / "ts_report_msgs")
    assert before != own
    two_packages(root, depth_type="float64")     # only the package it uses changed
    assert source_digest(root / "ts_report_msgs") == own
    assert build_digest(root / "ts_report_msgs") != before


@pytest.mark.slow(seconds=45)
@pytest.mark.timeout(400)
def test_ros_interfaces_builds_a_package_using_another_with_an_action_and_runs_a_program(tmp_path):
    # a package using another's type, in a message and in an action. The other is a copy of
    # the demo's turtlesim: the same files, so the same build key, and the run's turtlesim
    # build (tests/conftest.py starts it) serves this test too; the test waits for it under
    # the cache's lock, or makes it when run alone
    root = tmp_path / "interfaces"
    shutil.copytree(ROOT / "msg_samples" / "turtlesim", root / "turtlesim")
    assert build_digest(root / "turtlesim") == build_digest(ROOT / "msg_samples" / "turtlesim")
    report = root / "ts_report_msgs"
    (report / "msg").mkdir(parents=True)
    (report / "msg" / "Report.msg").write_text("turtlesim/Pose pose\nstring note\n")
    (report / "action").mkdir()
    (report / "action" / "Dive.action").write_text(
        "turtlesim/Pose target\n---\nfloat32 reached\n---\nfloat32 remaining\n")
    code = ("import rclpy, turtlesim.msg as t\n"
            "import ts_report_msgs.msg as r, ts_report_msgs.action as a\n"
            "from rclpy.serialization import serialize_message, deserialize_message\n"
            "m = r.Report(pose=t.Pose(x=12.5), note='ok')\n"
            "back = deserialize_message(serialize_message(m), r.Report)\n"
            "g = a.Dive.Goal(target=t.Pose(x=1.5))\n"
            "goal = deserialize_message(serialize_message(g), a.Dive.Goal)\n"
            "print(back.pose.x, back.note, goal.target.x)")
    env = {k: v for k, v in os.environ.items()
           if k not in ("LD_LIBRARY_PATH", "AMENT_PREFIX_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = str(ROOT)
    res = subprocess.run([sys.executable, "-m", "uwgen.cli", "ros-interfaces", str(root), "--",
                          sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=380)
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip().splitlines()[-1] == "12.5 ok 1.5"
    # what rclpy needs and no more: no C++ type support (it took as long again to build)
    cache = typesupport.interfaces_cache()
    libs = {p.name for pattern in ("ts_report_msgs-*", "turtlesim-*")
            for p in cache.glob(f"{pattern}/install/lib/*.so")}
    assert {"libts_report_msgs__rosidl_typesupport_fastrtps_c.so",
            "libturtlesim__rosidl_typesupport_fastrtps_c.so"} <= libs, libs
    assert not [name for name in libs if "_cpp" in name], libs


def test_prune_keeps_only_the_build_of_the_current_files(tmp_path, monkeypatch):
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path / "cache"))
    pkg = tmp_path / "pr_msgs"
    (pkg / "msg").mkdir(parents=True)
    (pkg / "msg" / "A.msg").write_text("int32 x\n")
    current = build_dir("pr_msgs", build_digest(pkg))
    old = build_dir("pr_msgs", "0123456789abcdef")
    other = build_dir("pr_msgs_extra", "0123456789abcdef")   # another package, same prefix
    for d in (current, old, other):
        d.mkdir(parents=True)
    assert typesupport.prune(pkg) == [old]
    assert current.is_dir() and other.is_dir() and not old.exists()


def test_broken_definitions_are_located_before_any_cmake_runs(tmp_path, capsys, monkeypatch):
    from uwgen.cli import main as uwgen_main
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path / "cache"))
    (tmp_path / "bad_msgs" / "msg").mkdir(parents=True)
    (tmp_path / "bad_msgs" / "msg" / "A.msg").write_text("int32 x\nint33 y\n")
    (tmp_path / "bad_msgs" / "msg" / "B.msg").write_text("string[ z\n")
    assert uwgen_main(["ros-interfaces", str(tmp_path)]) == 2    # broken definitions: an input error
    err = capsys.readouterr().err
    assert "A.msg:2:" in err and "B.msg:1:" in err
    assert not (tmp_path / "cache").exists()     # nothing was built


def test_one_package_given_alone_still_sees_the_one_it_uses(tmp_path, monkeypatch):
    from uwgen.commands.ros_interfaces import _check_definitions
    from uwgen.typesupport import local_dependencies
    root = two_packages(tmp_path / "interfaces")
    report = root / "ts_report_msgs"
    assert local_dependencies(report) == [root / "ts_base_msgs"]
    _check_definitions([report, *local_dependencies(report)])   # no unknown-type error
