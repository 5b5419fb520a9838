"""docs/walkthrough.md, followed literally: its shell blocks run as written, in order.

Each block of the page is marked `<!-- walkthrough: KIND -->`: `setup` (activating the
venv: the test puts this venv's bin/ first on PATH instead), `run` (must exit 0),
`background NAME` (must keep running until the end), `expect TEXT` (must exit 0 and print
TEXT). Two substitutions keep the test from colliding with other runs on the machine:
the page's ports 4710/4711 become free ports and its ROS domains 21/22 become domains of
this test. The user's own message must cross the emulated link: the subscriber on the
surface's domain prints what the talker published on the vehicle's.
"""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from ros_domains import next_domain
from uwgen import tether

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "walkthrough.md"
BLOCK = re.compile(r"<!-- walkthrough: (\w+) ?([^\n]*?) -->\n```sh\n(.*?)^```", re.S | re.M)
PORTS = ("4710", "4711")
DOMAINS = ("ROS_DOMAIN_ID=21", "ROS_DOMAIN_ID=22")


def blocks() -> list[tuple[str, str, str]]:
    return [(kind, arg.strip(), body) for kind, arg, body in BLOCK.findall(PAGE.read_text())]


def free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def test_the_page_has_every_step_marked():
    kinds = [k for k, _, _ in blocks()]
    assert kinds.count("run") >= 3 and kinds.count("background") == 4 and kinds[-1] == "expect"
    # Every shell block of the page is marked: nothing a reader copies goes untested.
    assert PAGE.read_text().count("```sh") == len(kinds)


@pytest.mark.slow(seconds=50)
@pytest.mark.timeout(600)
def test_walkthrough_own_message_crosses_the_emulated_link(tmp_path):
    ports = [str(p) for p in free_ports(2)]
    domains = [f"ROS_DOMAIN_ID={next_domain()}", f"ROS_DOMAIN_ID={next_domain()}"]

    def literal(text: str) -> str:
        for old, new in (*zip(PORTS, ports), *zip(DOMAINS, domains)):
            text = text.replace(old, new)
        return text

    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = str(ROOT)          # this checkout's uwgen, as the venv's own would be
    # The point: nothing of the kind set by hand. (The ROS wheels re-exec every Python with
    # their LD_LIBRARY_PATH once; a fresh terminal has neither it nor their guard variable.)
    for key in ("AMENT_PREFIX_PATH", "LD_LIBRARY_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE"):
        env.pop(key, None)
    env["PYTHONUNBUFFERED"] = "1"
    # One shell, as a reader's terminal: `cd auv_project` of a block holds for the next.
    cwd = tmp_path
    background: dict[str, tuple[subprocess.Popen, Path]] = {}
    try:
        for kind, arg, body in blocks():
            if kind == "setup":
                continue
            script = literal(body)
            if kind == "run":
                res = subprocess.run(["bash", "-e", "-c", script + "\npwd"], cwd=cwd, env=env,
                                     capture_output=True, text=True, timeout=400)
                assert res.returncode == 0, f"{script}\n{res.stdout}\n{res.stderr}"
                cwd = Path(res.stdout.strip().splitlines()[-1])
            elif kind == "background":
                log = tmp_path / f"{arg}.log"
                # One simple command: bash execs it, so the tether holds for it.
                proc = tether.popen(["bash", "-c", script], cwd=cwd, env=env,
                                    stdout=log.open("w"), stderr=subprocess.STDOUT,
                                    start_new_session=True)
                background[arg] = (proc, log)
            elif kind == "expect":
                res = subprocess.run(["bash", "-e", "-c", script], cwd=cwd, env=env,
                                     capture_output=True, text=True, timeout=120)
                logs = "\n".join(f"--- {n}\n{lg.read_text()}" for n, (_, lg) in background.items())
                assert res.returncode == 0, f"{res.stdout}\n{res.stderr}\n{logs}"
                assert arg in res.stdout, f"{res.stdout}\n{res.stderr}\n{logs}"
                for name, (proc, _) in background.items():
                    assert proc.poll() is None, f"{name} ended early:\n{logs}"
            else:
                pytest.fail(f"unknown walkthrough block kind {kind!r}")
        heard = [line for line in res.stdout.splitlines() if line.startswith("heard:")]
        assert len(heard) == 3 and all("mode survey" in line for line in heard)
        bridge_log = background["surface-bridge"][1].read_text()
        assert "not bridged" not in bridge_log and "no type support" not in bridge_log
    finally:
        for proc, _ in reversed(list(background.values())):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGINT)
        for proc, _ in background.values():
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)
