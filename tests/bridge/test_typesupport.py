"""uwgen.typesupport: where builds of your own interfaces live and how bridges find them."""
from pathlib import Path

import pytest

from uwgen import typesupport
from uwgen.typesupport import BuildError, activate_recorded, build_dir, cache_root, source_digest

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
    assert digest == source_digest(ROOT / "msg_samples" / "turtlesim")
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
