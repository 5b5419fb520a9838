"""`uwgen rmw-config`: export, import and beacons from the command line; bad input exits 2."""
from __future__ import annotations

import json

import pytest

from conftest import RMW_SAMPLE, SAMPLES
from uwgen.cli import main
from uwgen.idl.loader import InterfaceLibrary
from uwgen.manifest.loader import load_manifest


def run(capsys, *argv):
    code = main(["rmw-config", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_prints_the_table(capsys):
    code, out, _ = run(capsys, "export", "-m", RMW_SAMPLE, "-I", SAMPLES)
    assert code == 0
    assert out == (RMW_SAMPLE / "ros_allowed_topics.conf").read_text()


def test_export_writes_a_file(capsys, tmp_path):
    target = tmp_path / "conf" / "ros_allowed_topics.conf"
    code, out, err = run(capsys, "export", "-m", RMW_SAMPLE / "uwgen.yaml", "-I", SAMPLES,
                         "-o", target)
    assert code == 0 and out == ""
    assert json.loads(target.read_text())["topics"]["/turtle1/cmd_vel"] == 4
    assert "5 names" in err


def test_export_of_a_missing_or_broken_manifest_exits_2(capsys, tmp_path):
    code, _, err = run(capsys, "export", "-m", tmp_path / "nope.yaml")
    assert code == 2 and "no such manifest" in err
    with pytest.raises(SystemExit) as stop:      # -m's own check, as in every command
        run(capsys, "export", "-m", tmp_path)
    assert stop.value.code == 2 and "is a folder without a uwgen.yaml" in capsys.readouterr().err
    (tmp_path / "uwgen.yaml").write_text("network: x\nsides: {a: {port: 4000}}\ntopics:\n"
                                         "  - {name: /a, id: 1, type: std_msgs/msg/Bool, "
                                         "publisher: a, profile: rmw_desert}\n")
    code, _, err = run(capsys, "export", "-m", tmp_path)
    assert code == 2 and "uwgen.yaml:4:" in err and "reserved" in err


def test_import_writes_a_manifest_that_loads(capsys, tmp_path):
    out = tmp_path / "net" / "uwgen.yaml"
    code, _, err = run(capsys, "import", RMW_SAMPLE / "ros_allowed_topics.conf",
                       "--side-of", "/turtle1/cmd_vel=surface", "--default-side", "vehicle",
                       "--side", "vehicle=4011", "-I", SAMPLES, "-o", out)
    assert code == 0, err
    manifest = load_manifest(out, InterfaceLibrary(folders=[SAMPLES]))
    assert {s.name: s.port for s in manifest.sides.values()} == {"vehicle": 4011, "surface": 4000}
    assert [(t.name, t.publisher) for t in manifest.topics] == [
        ("/turtle1/cmd_vel", "surface"), ("/turtle1/pose", "vehicle")]
    assert manifest.services[0].server == "vehicle"
    assert list(out.parent.iterdir()) == [out]  # no temporary file left behind


def test_import_with_explicit_types_and_hints_file(capsys, tmp_path):
    conf = tmp_path / "ids.conf"
    conf.write_text('{"topics": {"/discovery": 1, "/discovery_request": 2, "/depth": 7, '
                    '"/arm": 8}}')
    hints = tmp_path / "hints.yaml"
    hints.write_text("/arm: std_srvs/srv/SetBool\n")
    out = tmp_path / "uwgen.yaml"
    code, _, err = run(capsys, "import", conf, "--type", "/depth=Float32", "--types", hints,
                       "--side-of", "/depth=auv", "--side-of", "/arm=auv", "-o", out)
    assert code == 0, err
    manifest = load_manifest(out, InterfaceLibrary())
    assert [(t.name, t.type_name) for t in manifest.topics] == [("/depth", "std_msgs/msg/Float32")]
    assert [(s.name, s.type_name) for s in manifest.services] == [("/arm", "std_srvs/srv/SetBool")]


@pytest.mark.parametrize("extra, message", [
    ([], "missing: /turtle1/cmd_vel"),
    (["--side-of", "/nope=a", "--default-side", "a"], "not in"),
    (["--default-side", "bad-name"], "side name 'bad-name'"),
    (["--default-side", "a", "--side", "a=port"], "expected PORT or HOST:PORT"),
    (["--default-side", "a", "--side-of", "/turtle1/pose"], "expected NAME=VALUE"),
    (["--default-side", "a", "--no-builtin-hints"], "/turtle1/cmd_vel: type unknown"),
    (["--default-side", "a", "--network", "Bad"], "network 'Bad'"),
])
def test_import_errors_exit_2_and_say_what_to_fix(capsys, tmp_path, extra, message):
    out = tmp_path / "uwgen.yaml"
    code, _, err = run(capsys, "import", RMW_SAMPLE / "ros_allowed_topics.conf", "-I", SAMPLES,
                       "-o", out, *extra)
    assert code == 2
    assert message in err
    assert not out.exists()


def test_import_refuses_to_overwrite_without_force(capsys, tmp_path):
    out = tmp_path / "uwgen.yaml"
    out.write_text("keep me")
    args = ["import", RMW_SAMPLE / "ros_allowed_topics.conf", "-I", SAMPLES,
            "--default-side", "a", "-o", out]
    code, _, err = run(capsys, *args)
    assert code == 2 and "--force" in err and out.read_text() == "keep me"
    code, _, err = run(capsys, *args, "--force")
    assert code == 0 and "network: rmw_desert" in out.read_text()


def test_import_of_a_bad_conf_exits_2_with_its_location(capsys, tmp_path):
    conf = tmp_path / "ids.conf"
    conf.write_text('{"topics": {\n  "/a": 4\n  "/b": 5}}')
    code, _, err = run(capsys, "import", conf, "--default-side", "a", "-o", tmp_path / "m.yaml")
    assert code == 2 and f"{conf}:3:3: not valid JSON" in err
    code, _, err = run(capsys, "import", tmp_path / "none.conf", "--default-side", "a",
                       "-o", tmp_path / "m.yaml")
    assert code == 2 and "none.conf not found" in err


def test_beacons_lists_the_side_entities(capsys):
    code, out, _ = run(capsys, "beacons", "-m", RMW_SAMPLE, "-I", SAMPLES, "--side", "vehicle",
                       "--frames")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith("subscriber /turtle1/cmd_vel  geometry_msgs__msg/Twist")
    assert lines[1].startswith("  99 99 ")
    assert "service    /turtle1/teleport_absolute  turtlesim__srv/TeleportAbsolute_Response" in out
    code, _, err = run(capsys, "beacons", "-m", RMW_SAMPLE, "-I", SAMPLES, "--side", "diver")
    assert code == 2 and "sides: surface, vehicle" in err


def test_no_action_exits_2(capsys):
    code, _, err = run(capsys)
    assert code == 2 and "export, import or beacons" in err
