"""One way to say things on the command line, checked with the real `uwgen` command:
-m takes a file or a folder everywhere, interface folders are DIR arguments everywhere
(old spellings work, with a note), defaults are shown, and every error exits 2."""
from __future__ import annotations

import argparse
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from uwgen.cli import build_parser
from uwgen.commands.options import all_parsers

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"
UWGEN = Path(sys.executable).parent / "uwgen"


def uwgen(*args, cwd=ROOT, timeout=120):
    return subprocess.run([str(UWGEN), *map(str, args)], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


# -- -m: a file or a folder, in every command that has it --------------------------------

def test_every_manifest_option_takes_a_file_or_a_folder():
    parser = build_parser()
    found = []
    for p in all_parsers(parser):
        for action in p._actions:
            if "-m" in action.option_strings:
                found.append(p.prog)
                assert action.type(str(SAMPLES)) == SAMPLES / "uwgen.yaml", p.prog
                assert action.type(str(SAMPLES / "uwgen.yaml")) == SAMPLES / "uwgen.yaml", p.prog
    assert {"uwgen build", "uwgen analyze", "uwgen bridge", "uwgen emulate",
            "uwgen rmw-config export", "uwgen rmw-config beacons"} <= set(found)


def test_bridge_takes_the_manifests_folder():
    res = uwgen("bridge", "-m", "msg_samples", "--side", "boat")
    assert res.returncode == 2 and "side 'boat'" in res.stderr     # found, read, then refused


def test_analyze_takes_the_manifests_folder():
    res = uwgen("analyze", "-m", "msg_samples")
    assert res.returncode == 0, res.stderr
    assert "network demo" in res.stdout


def test_emulate_takes_the_manifests_folder(tmp_path):
    a, b = free_ports(2)
    (tmp_path / "uwgen.yaml").write_text(f"network: em\nsides:\n  surface: {{port: {a}}}\n"
                                         f"  vehicle: {{port: {b}}}\n")
    res = uwgen("emulate", "-m", tmp_path, "--duration", "0.5")
    assert res.returncode == 0, res.stderr
    assert "surface" in res.stdout + res.stderr and "vehicle" in res.stdout + res.stderr


def test_a_folder_without_a_manifest_is_a_clear_error(tmp_path):
    res = uwgen("bridge", "-m", tmp_path, "--side", "vehicle")
    assert res.returncode == 2 and f"{tmp_path} is a folder without a uwgen.yaml" in res.stderr


# -- interface folders: DIR arguments everywhere ---------------------------------------

def test_interface_folders_are_dir_arguments_in_every_command():
    for p in all_parsers(build_parser()):
        for action in p._actions:
            if action.metavar == "DIR" and action.dest in ("folders", "interfaces"):
                assert not action.option_strings, f"{p.prog}: {action.option_strings}"


def test_rmw_config_takes_interface_folders_as_arguments_and_the_old_i_with_a_note(tmp_path):
    new = uwgen("rmw-config", "export", "-m", "msg_samples", "msg_samples")
    assert new.returncode == 0, new.stderr
    assert "note" not in new.stderr
    old = uwgen("rmw-config", "export", "-m", "msg_samples", "-I", "msg_samples")
    assert old.returncode == 0, old.stderr
    assert old.stdout == new.stdout
    assert "note: -I is now a DIR argument" in old.stderr


# -- demo --side: a square's size, now --square-size ------------------------------------

def test_demo_square_size_and_its_old_spelling():
    parser = build_parser("demo")
    assert parser.parse_args(["demo", "--square-size", "2"]).square_size == 2.0
    assert parser.parse_args(["demo", "--side", "3"]).square_size == 3.0
    assert parser.parse_args(["demo"]).square_size == 4.0
    res = uwgen("demo", "--side", "2", "--desert", "127.0.0.1:9,127.0.0.1:9", timeout=60)
    assert "note: --side is now --square-size" in res.stderr
    help_text = uwgen("demo", "--help").stdout
    assert "--square-size" in help_text and "--side" not in help_text


# -- help: defaults shown, actions named -----------------------------------------------

def test_every_option_with_a_default_shows_it_in_help():
    missing = []
    for p in all_parsers(build_parser()):
        formatter = p._get_formatter()
        for action in p._actions:
            if not action.option_strings or action.help in (None, argparse.SUPPRESS):
                continue
            if action.default in (None, False, [], argparse.SUPPRESS):
                continue
            if "default" not in formatter._expand_help(action).lower():
                missing.append(f"{p.prog} {action.option_strings[0]}")
    assert missing == []


def test_help_shows_defaults_the_real_command_prints():
    res = uwgen("demo", "--help")
    text = " ".join(res.stdout.split())
    assert "(default: 300.0)" in text and "(default: 4.0)" in text and "(default: 180.0)" in text
    text = " ".join(uwgen("bridge", "--help").stdout.split())
    assert "default: the manifest's side entry" in text


def test_actions_are_named_in_the_top_level_and_build_help():
    top = " ".join(uwgen("--help").stdout.split())
    assert "topics, services and actions" in top
    build = " ".join(uwgen("build", "--help").stdout.split())
    assert ".action" in build and "pkg/action/Name" in build


# -- emulate: --ports does not swallow the scenario; a taken port exits 2 --------------

def test_emulate_ports_then_a_scenario_file(tmp_path):
    a, b = free_ports(2)
    res = uwgen("emulate", "--ports", a, b, SAMPLES / "scenarios" / "two-nodes.yaml", "--duration", "0.5")
    assert res.returncode == 0, res.stderr
    out = res.stdout + res.stderr
    assert f":{a}" in out and f":{b}" in out
    assert "surface" in out and "vehicle" in out          # the file's nodes, moved to these ports


def test_emulate_ports_that_are_not_ports_exit_2():
    res = uwgen("emulate", "--ports", "4000", "x.yaml", "y.yaml")
    assert res.returncode == 2 and "--ports: expected port numbers" in res.stderr


def test_a_taken_port_exits_2_like_every_other_error():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        (other,) = free_ports(1)
        res = uwgen("emulate", "--ports", port, other, "--duration", "0.5")
    assert res.returncode == 2, res.stderr
    assert f"cannot listen on 127.0.0.1:{port}" in res.stderr


# -- ros-interfaces --print-env: what the walkthrough says ---------------------------------

def test_print_env_prints_the_three_variables_the_walkthrough_names():
    res = uwgen("ros-interfaces", SAMPLES / "turtlesim", "--print-env", timeout=400)
    assert res.returncode == 0, res.stderr
    keys = [line.split("=", 1)[0] for line in res.stdout.splitlines()]
    assert keys == ["export PYTHONPATH", "export AMENT_PREFIX_PATH", "export LD_LIBRARY_PATH"]
    page = " ".join((ROOT / "docs" / "walkthrough.md").read_text().split())
    assert ("prints the three variables such a program needs (`PYTHONPATH`, "
            "`AMENT_PREFIX_PATH`, `LD_LIBRARY_PATH`)") in page
