"""A copy of a generated package works without uwgen: stdlib and cbor2 alone (plain
classes), and decodes into rclpy classes where rclpy is importable.

Each check runs `python -I -S` (no site-packages, no .pth files, no PYTHONPATH) with a
sys.path of only the copied package's parent folder and a folder holding cbor2.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import cbor2
import pytest

from uwgen.codegen import generate
from uwgen.codegen.vendor import CARRIED

ROOT = Path(__file__).resolve().parents[2]

PLAIN_ROUND_TRIP = r"""
import json, sys
sys.path[:0] = json.loads(sys.argv[1])
import uwgen_demo
from uwgen_demo.geometry_msgs.msg import Twist, Vector3
from uwgen_demo.turtlesim.srv import SetPen
assert not any(m == "uwgen" or m.startswith("uwgen.") for m in sys.modules), "uwgen was imported"
try:
    import uwgen
    raise SystemExit("uwgen is importable: the test is not isolated")
except ImportError:
    pass
cmd = uwgen_demo.TOPICS[4]
payload = cmd.encode(Twist(linear=Vector3(x=0.5), angular=Vector3(z=-0.25)))
back = cmd.decode(payload)              # no rclpy here: the plain class
assert type(back) is Twist and back == Twist(linear=Vector3(x=0.5), angular=Vector3(z=-0.25)), back
pen = uwgen_demo.SERVICES[21]
seq, req = pen.decode_request(pen.encode_request(7, SetPen.Request(r=255, width=3)))
assert seq == 7 and (req.r, req.width) == (255, 3)
try:
    cmd.decode(payload[:-1])
    raise SystemExit("a cut payload decoded")
except uwgen_demo._runtime.codec.DecodeError as exc:
    error = str(exc)
print(json.dumps({"payload": payload.hex(), "error": error,
                  "runtime": uwgen_demo._runtime.table.__file__}))
"""

ROS_DECODE = r"""
import json, sys
sys.path[:0] = json.loads(sys.argv[1])
import uwgen_demo
from uwgen_demo.geometry_msgs.msg import Twist, Vector3
assert "uwgen" not in sys.modules
cmd = uwgen_demo.TOPICS[4]
msg = cmd.decode(cmd.encode(Twist(linear=Vector3(x=0.5))))
import geometry_msgs.msg
assert type(msg) is geometry_msgs.msg.Twist and msg.linear.x == 0.5, type(msg)
ros_payload = cmd.encode(geometry_msgs.msg.Twist(linear=geometry_msgs.msg.Vector3(x=0.5)))
print(json.dumps({"type": type(msg).__module__, "payload": ros_payload.hex()}))
"""


# Exactly the calls the package's docstring lists, in a copy without uwgen.
DOCUMENTED_CALLS = r"""
import json, sys
sys.path[:0] = json.loads(sys.argv[1])
import uwgen_demo
from uwgen_demo import ACCEPTED, SUCCEEDED, codec, ACTIONS, SERVICES, TOPICS
from uwgen_demo.turtlesim.msg import Color, Pose
from uwgen_demo.turtlesim.srv import TeleportAbsolute
from uwgen_demo.turtlesim.action import RotateAbsolute
assert "uwgen" not in sys.modules
out = {}
data = codec("turtlesim/msg/Color").encode(Color(r=255, g=1, b=2))     # a bare message
assert codec("turtlesim/msg/Color").decode_message(data) == Color(r=255, g=1, b=2)
out["bare"] = data.hex()
payload = TOPICS[5].encode(Pose(x=1.5, y=2.0))
assert (TOPICS[5].decode(payload).x, TOPICS[5].decode(payload).y) == (1.5, 2.0)
tele = SERVICES[20]
seq, req = tele.decode_request(tele.encode_request(3, TeleportAbsolute.Request(x=1.0, y=2.0)))
assert seq == 3 and (req.x, req.y) == (1.0, 2.0)
seq, resp = tele.decode_response(tele.encode_response(3, TeleportAbsolute.Response()))
assert seq == 3 and type(resp) is TeleportAbsolute.Response
rot = ACTIONS[30]
assert rot.decode_request(rot.encode_goal(2, RotateAbsolute.Goal(theta=1.5))) == (2, RotateAbsolute.Goal(theta=1.5))
assert rot.decode_request(rot.encode_cancel(2)) == (2, None)
assert rot.decode_response(rot.encode_answer(2, ACCEPTED)) == (2, ACCEPTED, None)
assert rot.decode_response(rot.encode_result(2, SUCCEEDED, RotateAbsolute.Result(delta=0.5))) == \
    (2, SUCCEEDED, RotateAbsolute.Result(delta=0.5))
assert rot.decode_feedback(rot.encode_feedback(2, RotateAbsolute.Feedback(remaining=0.25))) == \
    (2, RotateAbsolute.Feedback(remaining=0.25))
try:
    codec("geometry_msgs/msg/Twist")
except KeyError as exc:
    out["missing"] = str(exc)
out["doc"] = uwgen_demo.__doc__
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def vendored(tmp_path_factory):
    """generated/uwgen_demo copied into a folder of its own, and cbor2 into another."""
    base = tmp_path_factory.mktemp("vendored")
    shutil.copytree(ROOT / "generated" / "uwgen_demo", base / "project" / "uwgen_demo",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(Path(cbor2.__file__).parent, base / "deps" / "cbor2",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return base


def isolated(code: str, paths: list[Path]) -> dict:
    res = subprocess.run([sys.executable, "-I", "-S", "-c", code, json.dumps([str(p) for p in paths])],
                         capture_output=True, text=True, timeout=60, cwd="/")
    assert res.returncode == 0, res.stdout + res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_copy_round_trips_with_stdlib_and_cbor2_alone(vendored):
    out = isolated(PLAIN_ROUND_TRIP, [vendored / "project", vendored / "deps"])
    # The copy's own runtime ran, and wrote the same bytes as uwgen's.
    assert out["runtime"].startswith(str(vendored / "project" / "uwgen_demo" / "_runtime"))
    from uwgen.bridge.plan import import_package
    from geometry_msgs.msg import Twist, Vector3
    demo = import_package("uwgen_demo", ROOT / "generated")
    assert bytes.fromhex(out["payload"]) == demo.TOPICS[4].encode(
        Twist(linear=Vector3(x=0.5), angular=Vector3(z=-0.25)))
    assert "items" in out["error"] or "payload" in out["error"] or "CBOR" in out["error"]


def test_copy_decodes_into_rclpy_classes_where_rclpy_is_present(vendored):
    # The venv's site-packages gives rclpy and geometry_msgs; uwgen (an editable install,
    # found through a .pth file that -I skips) stays unimportable.
    site = Path(sysconfig.get_paths()["purelib"])
    out = isolated(ROS_DECODE, [vendored / "project", site])
    assert out["type"].startswith("geometry_msgs.msg")
    assert bytes.fromhex(out["payload"]).startswith(b"\x00\x04")


def test_generated_package_uses_uwgens_runtime_when_it_is_the_same():
    from uwgen.bridge.plan import import_package
    import uwgen.runtime.wire.codec
    import uwgen.runtime.wire.table
    demo = import_package("uwgen_demo", ROOT / "generated")
    # One set of classes per process: a bridge catches what the generated codecs raise.
    assert demo._runtime.codec is uwgen.runtime.wire.codec
    assert type(demo.TOPICS[4]) is uwgen.runtime.wire.table.TopicCodec


def test_every_carried_module_is_copied_and_imports_only_carried_ones(tmp_path):
    pkg = generate(tmp_path, "uwgen_vend", ["std_msgs/msg/String"])
    folder = Path(pkg.__file__).parent / "_runtime"
    assert sorted(p.stem for p in folder.glob("*.py")) == sorted([*CARRIED, "__init__"])
    for name in CARRIED:
        text = (folder / f"{name}.py").read_text()
        code = [line for line in text.splitlines() if line.lstrip().startswith(("from ", "import "))
                and "TYPE_CHECKING" not in line]
        assert not [line for line in code if line.lstrip().startswith(("from uwgen", "import uwgen"))
                    and not line.startswith("    ")], name


def test_bridge_refuses_a_package_generated_by_another_uwgen(tmp_path):
    shutil.copytree(ROOT / "generated" / "uwgen_demo", tmp_path / "uwgen_demo",
                    ignore=shutil.ignore_patterns("__pycache__"))
    init = tmp_path / "uwgen_demo" / "_runtime" / "__init__.py"
    init.write_text(init.read_text().replace("'uwgen.runtime.wire.codec', '", "'uwgen.runtime.wire.codec', 'x"))
    res = subprocess.run([sys.executable, "-m", "uwgen_demo.bridge_vehicle"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=60,
                         env={**__import__("os").environ, "PYTHONPATH": f"{tmp_path}:{ROOT}"})
    assert res.returncode == 2, res.stderr
    assert "generated by another version of uwgen" in res.stderr and "uwgen build" in res.stderr


def test_the_calls_the_package_documents_work_in_a_copy(vendored):
    out = isolated(DOCUMENTED_CALLS, [vendored / "project", vendored / "deps"])
    assert bytes.fromhex(out["bare"]) == cbor2.dumps(255) + cbor2.dumps(1) + cbor2.dumps(2)   # fields only
    for call in ('codec("pkg/msg/Name").encode(msg)', ".decode_message(data)", "TOPICS[id].encode(msg)",
                 "encode_request(seq, request)", "decode_response(payload)", "encode_goal(handle, goal)",
                 "encode_cancel(handle)", "encode_answer(handle, ACCEPTED)",
                 "encode_result(handle, SUCCEEDED, result)", "decode_feedback(payload)"):
        assert call in out["doc"], call
    # Twist is built only with the manifest's field encodings: the error says where to look.
    assert "TOPICS" in out["missing"] and "geometry_msgs/msg/Twist" in out["missing"]


def test_the_readme_points_to_the_documented_calls():
    text = " ".join((ROOT / "README.md").read_text().split())
    assert "codec(type_name).encode(msg)" in text and "help(uwgen_demo)" in text
