"""`uwgen bridge -m /abs/path/uwgen.yaml` run from another folder finds the manifest's
relative key_file next to the manifest it was given, and a missing key is reported without
inviting a new one (a new key would split the network). The real `uwgen` command."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uwgen import tether

UWGEN = Path(sys.executable).parent / "uwgen"
MANIFEST = """\
network: keyed
security: {mode: encrypt, key_file: keys/net.key}
sides:
  surface: {port: 4000, sender_id: 1}
  vehicle: {port: 4001, sender_id: 2}
topics:
  - {name: /cmd_vel, id: 4, type: geometry_msgs/msg/Twist, publisher: surface}
"""


def uwgen(*args, cwd):
    return subprocess.run([str(UWGEN), *map(str, args)], cwd=cwd, capture_output=True, text=True,
                          timeout=120)


@pytest.fixture
def project(tmp_path):
    """proj/{uwgen.yaml, keys/net.key, generated/uwgen_keyed}, built in proj."""
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "uwgen.yaml").write_text(MANIFEST)
    assert uwgen("keygen", "keys/net.key", cwd=proj).returncode == 0
    res = uwgen("build", "-m", "uwgen.yaml", cwd=proj)
    assert res.returncode == 0, res.stderr
    return proj


def start_bridge(manifest: Path, cwd: Path) -> tuple[int, str]:
    """Run the vehicle's bridge until it says how its link is secured (or exits); its exit
    status (SIGINT after the secure-link line) and what it logged."""
    proc = tether.popen([str(UWGEN), "bridge", "-m", str(manifest), "--side", "vehicle",
                         "--port", "9", "--status-period", "0"], cwd=cwd,
                        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    lines = []
    deadline = time.monotonic() + 60
    try:
        for line in proc.stderr:
            lines.append(line)
            if "secure link" in line or time.monotonic() > deadline:
                proc.send_signal(signal.SIGINT)
                break
        rest, _ = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, "".join(lines) + (rest or "")


def test_a_relative_key_file_is_found_next_to_the_manifest_given(project, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    rc, log = start_bridge(project / "uwgen.yaml", elsewhere)
    assert "secure link" in log and f"key {project / 'keys' / 'net.key'}" in log, log
    assert rc == 0, log


def test_a_missing_key_says_to_copy_the_networks_key_not_to_make_one(project, tmp_path):
    (project / "keys" / "net.key").unlink()
    res = uwgen("bridge", "-m", project / "uwgen.yaml", "--side", "vehicle", cwd=tmp_path)
    assert res.returncode == 2
    assert f"{project / 'keys' / 'net.key'}" in res.stderr
    assert "copy" in res.stderr and "--key-file" in res.stderr
    assert "create one" not in res.stderr and "uwgen keygen keys" not in res.stderr
