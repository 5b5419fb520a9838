"""`uwgen demo` options: against a running DESERT (--desert), quiet, read-only checkout;
`uwgen --version`."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import argparse
import pytest

from uwgen import tether
from uwgen.commands import demo
from uwgen.emulator import NodeSpec, Scenario, run_emulator

from .recordings_check import check_recordings

ROOT = Path(__file__).resolve().parents[2]


def uwgen(*args, timeout=60):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return tether.run([sys.executable, "-m", "uwgen.cli", *args], capture_output=True,
                      text=True, timeout=timeout, env=env, cwd=ROOT)


def test_version_is_printed():
    res = uwgen("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"uwgen {__import__('uwgen').__version__}"


def test_desert_endpoints_are_parsed_and_checked():
    assert demo.desert_endpoints("10.0.0.1:4000,modem2:4001") == {
        "surface": ("10.0.0.1", 4000), "vehicle": ("modem2", 4001)}
    for bad in ("10.0.0.1:4000", "a:1,b:2,c:3", "a:x,b:2", "a:0,b:2", ":4000,b:2"):
        with pytest.raises(argparse.ArgumentTypeError):
            demo.desert_endpoints(bad)


def test_read_only_checkout_writes_to_the_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path))
    monkeypatch.setattr(demo.os, "access", lambda path, mode: False)
    assert demo.default_out() == tmp_path / "demo_output"
    from uwgen.typesupport import build_dir
    assert tmp_path in build_dir("turtlesim", "0" * 16).parents   # turtlesim's build too
    from uwgen.demo.keys import demo_key
    with demo_key(demo.DEMO_MANIFEST, tmp_path / "out") as key:    # and the network key
        assert key.path == tmp_path / "demo" / "keys" / "demo.key" and key.created


@pytest.mark.slow(seconds=60)
@pytest.mark.timeout(300)
def test_demo_runs_against_a_running_desert_quietly_and_its_recordings_reproduce_the_report(tmp_path):
    # One demo run (about a minute) serves two checks: what it prints and what it recorded.
    # A DESERT someone else started (here the emulator, as another program would be).
    scen = Scenario(nodes=[NodeSpec("s", port=0, position=(0.0, 0.0, 0.0), dest="v"),
                           NodeSpec("v", port=0, position=(300.0, 0.0, 0.0), dest="s")],
                    period=0.2, max_read_length=64, bitrate=4800.0, per=0.0, seed=3)
    with run_emulator(scen) as emu:
        res = uwgen("--quiet", "demo", "--desert", f"127.0.0.1:{emu.port('s')},127.0.0.1:{emu.port('v')}",
                    "--square-size", "1", "--out", str(tmp_path), "--timeout", "150",
                    "--key-file", str(tmp_path / "keys" / "demo.key"), timeout=220)
        counters = emu.all_counters()
    assert res.returncode == 0, res.stdout + res.stderr
    # The demo used the given nodes, started no emulator of its own.
    assert counters["s"]["packets_delivered"] > 10 and counters["v"]["packets_delivered"] > 10
    assert "emulated" not in res.stdout
    assert "the vehicle followed the commands" in res.stdout
    # The secure link was on (docs/security.md): both bridges protected and verified, nothing dropped.
    import json
    import re
    why = r"(?: \((?:[a-z_]+ \d+(?:, )?)+\))?"
    security = re.search(rf"^security: surface protected (\d+) verified (\d+) dropped (\d+){why}; "
                         rf"vehicle protected (\d+) verified (\d+) dropped (\d+){why}$", res.stdout, re.M)
    assert security, res.stdout
    s_prot, s_ver, s_drop, v_prot, v_ver, v_drop = map(int, security.groups())
    assert min(s_prot, s_ver, v_prot, v_ver) > 0
    # A genuine run drops nothing but, at most, frames sealed before the other bridge started
    # (still queued in DESERT then: a bridge cannot tell them from replays).
    for side, dropped in (("surface", s_drop), ("vehicle", v_drop)):
        status = json.loads((tmp_path / f"bridge_{side}.json").read_text())["security"]
        assert status["dropped"] == dropped == status["before_start"], status
    vehicle = json.loads((tmp_path / "bridge_vehicle.json").read_text())["security"]
    assert vehicle["verified"] == v_ver and vehicle["unprotected"] == 0
    assert "/turtle1/cmd_vel 21 B = 13 B with packed + field encodings + 8 B encrypt" in res.stdout
    # Quiet: the report and nothing else; no INFO line from any part, and no ERROR line for
    # what a lossy link does in normal operation.
    assert "INFO" not in res.stdout + res.stderr
    assert "ERROR" not in res.stdout + res.stderr and "Traceback" not in res.stderr
    assert "[bridge_" not in res.stdout and "[operator]" not in res.stdout
    check_recordings(tmp_path, res.stdout)


def test_quiet_build_prints_no_info_lines(tmp_path):
    pkg = tmp_path / "q_msgs" / "msg"
    pkg.mkdir(parents=True)
    (pkg / "Q.msg").write_text("int32 x\n")
    loud = uwgen("build", str(tmp_path), "-o", str(tmp_path / "a"))
    assert loud.returncode == 0 and "INFO" in loud.stderr
    quiet = uwgen("--quiet", "build", str(tmp_path), "-o", str(tmp_path / "b"))
    assert quiet.returncode == 0 and quiet.stderr == "" and quiet.stdout == ""


@pytest.mark.parametrize("argv", [["--quiet", "demo"], ["demo", "--quiet"]])
def test_demo_quiet_silences_in_process_info_logs(monkeypatch, argv):
    import logging
    from uwgen.cli import main
    seen = {}
    monkeypatch.setattr(demo, "run", lambda args: seen.setdefault(
        "info", logging.getLogger("uwgen.emulator").isEnabledFor(logging.INFO)) and 0)
    assert main(argv) == 0
    assert seen == {"info": False}
    main(["demo"])   # and without it, the emulator's INFO lines are on again
    assert logging.getLogger("uwgen.emulator").isEnabledFor(logging.INFO)


def test_demo_says_when_the_given_desert_is_not_there(tmp_path):
    import socket
    with socket.socket() as s:          # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    res = uwgen("demo", "--desert", f"127.0.0.1:{port},127.0.0.1:{port}", "--out", str(tmp_path))
    assert res.returncode == 1
    assert f"cannot reach the DESERT node of surface at 127.0.0.1:{port}" in res.stderr
