"""A package with interfaces of its own, run with the real `uwgen` command: the advice after
a change builds rclpy's type support too, and a bridge that can bridge nothing says why and
exits instead of running on."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

UWGEN = Path(sys.executable).parent / "uwgen"
MANIFEST = """\
network: own
sides:
  surface: {port: 4000}
  vehicle: {port: 4001}
topics:
  - {name: /note, id: 4, type: own_msgs/msg/Note, publisher: vehicle}
"""


def uwgen(*args, cwd, env=None, timeout=120):
    return subprocess.run([str(UWGEN), *map(str, args)], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


@pytest.fixture
def project(tmp_path):
    """proj/interfaces/{own_msgs/msg/Note.msg, uwgen.yaml}, built (codecs only) from proj."""
    proj = tmp_path / "proj"
    (proj / "interfaces" / "own_msgs" / "msg").mkdir(parents=True)
    (proj / "interfaces" / "own_msgs" / "msg" / "Note.msg").write_text("string text\n")
    (proj / "interfaces" / "uwgen.yaml").write_text(MANIFEST)
    res = uwgen("build", "interfaces", cwd=proj)
    assert res.returncode == 0, res.stderr
    return proj


def test_the_advice_after_a_msg_change_builds_the_type_support_too(project, tmp_path):
    (project / "interfaces" / "own_msgs" / "msg" / "Note.msg").write_text("string text\nuint8 level\n")
    res = uwgen("bridge", "-m", project / "interfaces" / "uwgen.yaml", "--side", "vehicle", cwd=tmp_path)
    assert res.returncode == 2 and "Note.msg changed" in res.stderr
    assert f"cd {project} && uwgen build interfaces --ros" in res.stderr


def test_the_walkthrough_gives_the_same_advice():
    page = " ".join((Path(__file__).resolve().parents[2] / "docs" / "walkthrough.md").read_text().split())
    assert "After any change, run `uwgen build interfaces --ros` again" in page
    assert "run `uwgen build interfaces` again" not in page


def test_a_bridge_that_can_bridge_nothing_exits_with_the_reason(project, tmp_path):
    # Codecs built, rclpy's type support of own_msgs not (an empty cache): nothing of the
    # vehicle's side can be bridged.
    env = {**os.environ, "UWGEN_CACHE": str(tmp_path / "empty-cache")}
    res = uwgen("bridge", "-m", project / "interfaces" / "uwgen.yaml", "--side", "vehicle",
                "--port", "9", cwd=tmp_path, env=env, timeout=60)
    assert res.returncode == 2, res.stderr
    assert "nothing to bridge" in res.stderr and "/note" in res.stderr
    assert f"run `cd {project} && uwgen build interfaces --ros` first" in res.stderr
    assert "sends /note" not in res.stderr     # no INFO line claiming it bridges it
