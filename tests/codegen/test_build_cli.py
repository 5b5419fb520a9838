"""`uwgen build` from the command line: errors, --check, defaults, reproducibility."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


REPO = Path(__file__).resolve().parents[2]
UWGEN = [sys.executable, "-m", "uwgen.cli"]


def uwgen(*args, cwd=REPO):
    return subprocess.run([*UWGEN, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=120)


def write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


MANIFEST = """network: t
sides:
  a: {port: 4000}
  b: {port: 4001}
topics:
  - {name: /p, id: 3, type: pkg/msg/P, publisher: a}
"""


def test_build_with_only_a_folder_uses_its_manifest_by_convention(tmp_path):
    src = write(tmp_path / "interfaces", {"pkg/msg/P.msg": "int32 x\n", "uwgen.yaml": MANIFEST})
    result = uwgen("build", src, "-o", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    init = (tmp_path / "out" / "__init__.py").read_text()
    assert "Manifest: interfaces/uwgen.yaml" in init and "TOPICS = {" in init and "'/p'" not in init
    assert '"/p"' in init


def test_malformed_definition_is_reported_with_file_line_column_and_status_2(tmp_path):
    src = write(tmp_path / "defs", {"pkg/msg/P.msg": "int32 x\nfloat65 y\n"})
    result = uwgen("build", src, "-o", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2
    assert "P.msg:2:1:" in result.stderr and "float65" in result.stderr


def test_bad_manifest_is_reported_with_its_file_and_line(tmp_path):
    src = write(tmp_path / "defs", {"pkg/msg/P.msg": "int32 x\n",
                                    "uwgen.yaml": MANIFEST.replace("id: 3", "id: 300")})
    result = uwgen("build", src, "-o", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2
    assert "uwgen.yaml:6:" in result.stderr and "300" in result.stderr


def test_manifest_type_rmw_desert_cannot_carry_is_refused_at_build_time(tmp_path):
    manifest = MANIFEST.replace("type: pkg/msg/P", "type: nav_msgs/msg/Odometry, profile: rmw_desert")
    src = write(tmp_path / "defs", {"pkg/msg/P.msg": "int32 x\n", "uwgen.yaml": manifest})
    result = uwgen("build", src, "-o", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2
    assert "nav_msgs/msg/Odometry" in result.stderr and "64" in result.stderr


def test_check_reports_stale_output_and_passes_when_fresh(tmp_path):
    src = write(tmp_path / "defs", {"pkg/msg/P.msg": "int32 x\n"})
    out = tmp_path / "out"
    assert uwgen("build", src, "-o", out, "--check", cwd=tmp_path).returncode == 1
    assert uwgen("build", src, "-o", out, cwd=tmp_path).returncode == 0
    assert uwgen("build", src, "-o", out, "--check", cwd=tmp_path).returncode == 0
    (src / "pkg/msg/P.msg").write_text("int32 x\nint32 y\n")
    stale = uwgen("build", src, "-o", out, "--check", cwd=tmp_path)
    assert stale.returncode == 1 and "changed:" in stale.stderr


def test_output_is_byte_for_byte_reproducible(tmp_path):
    for out in ("one", "two"):
        assert uwgen("build", REPO / "msg_samples", "-o", tmp_path / out, cwd=REPO).returncode == 0
    one = {p.relative_to(tmp_path / "one"): p.read_bytes() for p in (tmp_path / "one").rglob("*.py")}
    two = {p.relative_to(tmp_path / "two"): p.read_bytes() for p in (tmp_path / "two").rglob("*.py")}
    assert one == two and len(one) > 5


def test_committed_generated_package_is_fresh():
    result = uwgen("build", "--check", cwd=REPO)
    assert result.returncode == 0, result.stderr


def test_unknown_folder_is_an_error_not_a_crash(tmp_path):
    result = uwgen("build", tmp_path / "nope", cwd=tmp_path)
    assert result.returncode == 2 and "nope" in result.stderr and "Traceback" not in result.stderr


def test_generated_package_imports_and_works_without_ros():
    """Block rclpy and every ROS message package: the codecs still encode and decode."""
    code = """
import sys, importlib.abc
class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        top = name.split('.')[0]
        if top in ('rclpy', 'rosidl_parser') or top.endswith(('_msgs', '_interfaces', '_srvs')):
            raise ImportError('ROS blocked: ' + name)
sys.meta_path.insert(0, NoRos())
sys.path.insert(0, 'generated')
import uwgen_demo
from uwgen_demo.geometry_msgs.msg import Twist, Vector3
topic = uwgen_demo.TOPICS[4]
payload = topic.encode(Twist(linear=Vector3(x=2.0), angular=Vector3(z=1.8)))
back = topic.decode(payload)
assert type(back) is Twist and back.angular.z == 1.8, back
assert 'rclpy' not in sys.modules
print(payload.hex())
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=60)
    assert result.returncode == 0, result.stderr
    # The demo sends cmd_vel packed with field encodings (wire format section 9): a 5-byte
    # string of linear.x 400 (9 bits), linear.z 0 (16 bits), angular.z 500 (9 bits), 6 pad bits.
    assert result.stdout.strip() == "0004" + "45" + "c800003e80"


def test_a_profile_only_build_leaves_out_services_whose_part_it_cannot_carry(tmp_path):
    from uwgen.codegen import generate
    pkg = generate(tmp_path, "uwgen_rmw_only", names=["nav_msgs/srv/SetMap", "std_srvs/srv/SetBool"],
                   profiles=("rmw_desert",))
    assert ("std_srvs/srv/SetBool_Request", "rmw_desert") in pkg.CODECS
    assert ("nav_msgs/srv/SetMap_Request", "rmw_desert") not in pkg.CODECS   # an OccupancyGrid: > 64 items
    import importlib
    assert not hasattr(importlib.import_module("uwgen_rmw_only.nav_msgs.srv"), "SetMap")
