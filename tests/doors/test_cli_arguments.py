"""The command-line door: any value of any number flag gives a clear usage error or a run;
never a traceback (OverflowError from 1e400 or a 400-digit number), never a run that does
not end (`uwgen emulate --nodes 100000000` built a hundred million nodes)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from .helpers import SAMPLES, cli, examples

HOSTILE = ["0", "-1", "1e400", "-1e400", "nan", "inf", "-inf", "1e-300", "9" * 400, "-" + "9" * 400,
           "1e9", "100000000", "0x10", "", " ", "1_000", "½", "abc"]
# Commands that end by themselves whatever their flags (emulate stops after --duration).
COMMANDS = {
    "analyze": (["analyze", SAMPLES], ["--bitrate"]),
    "emulate": (["emulate", "--duration", "0.05", "--ports", "0", "0"],
                ["--period", "--max-read-length", "--bitrate", "--per", "--seed", "--wind", "--distance",
                 "--tdma", "--guard", "--crash-every", "--crash-down"]),
    "emulate nodes": (["emulate", "--duration", "0.05"], ["--nodes"]),
    "pdr sweep": (["emulate", "--pdr-sweep", "--packets", "20"], ["--wind", "--per", "--bitrate"]),
    "packets": (["emulate", "--pdr-sweep", "--wind", "0"], ["--packets"]),
}
# Good values that run long by design: a sweep of 73 319 packets took 47 s (and failed the
# 20 s deadline below) although it ends, as it should. The door is what this test checks,
# so those are not drawn; the values around them (up to 2 000, and from 100 001 refused) are.
LONG_RUNS = {"packets": range(2_001, 100_001)}
# Flags of commands that run for minutes when given good values: only refusals are checked.
REFUSED_ONLY = {
    "emulate": ["--duration"],
    "demo": ["--distance", "--per", "--seed", "--square-size", "--side", "--laps", "--timeout", "--drive-to", "--drive-time", "--wind"],
    "bridge": ["--max-read-length", "--period", "--status-period"],
}


@pytest.mark.parametrize("flag, value, says", [
    ("--period", "1e400", "argument --period: must be a number in 0.001..3600, got 1e400"),
    ("--nodes", "100000000", "argument --nodes: must be a whole number in 1..256, got 100000000"),
    ("--seed", "9" * 400, "argument --seed: must be a whole number in 0..18446744073709551615, got '999999999999999999999999... (400 characters)'"),
    ("--duration", "nan", "argument --duration: must be a number in 0..1e+09, got nan"),
    ("--wind", "1e400", "argument --wind: must be a number in 0..100, got 1e400"),
])
def test_emulate_refuses_numbers_out_of_range_by_name(capsys, flag, value, says):
    rc, out = cli(capsys, "emulate", flag, value, "--duration" if flag != "--duration" else "--seed", "1")
    assert rc == 2 and says in out, out


def test_analyze_refuses_an_infinite_bitrate(capsys):
    rc, out = cli(capsys, "analyze", SAMPLES, "--bitrate", "1e400")
    assert rc == 2 and "argument --bitrate: must be a number in 1..1e+09, got 1e400" in out, out


@settings(max_examples=examples(120), deadline=20_000,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_any_number_flag_value_gives_a_usage_error_or_a_run_that_ends(capsys, data):
    command = data.draw(st.sampled_from(sorted(COMMANDS)))
    base, flags = COMMANDS[command]
    chosen = data.draw(st.lists(st.sampled_from(flags), min_size=1, max_size=3, unique=True))
    long_runs = LONG_RUNS.get(command, range(0))
    integers = st.integers().filter(lambda n: n not in long_runs)
    argv = list(base)
    for flag in chosen:
        argv += [flag, data.draw(st.sampled_from(HOSTILE) | st.floats().map(repr) | integers.map(str))]
    rc, out = cli(capsys, *argv)
    assert rc in (0, 1, 2), (argv, rc, out)
    assert "Traceback" not in out
    if rc == 2:
        assert "uwgen" in out and ("error" in out or ": " in out), out


@pytest.mark.parametrize("command", sorted(REFUSED_ONLY))
def test_long_running_commands_refuse_hostile_numbers_before_starting(capsys, command):
    for flag in REFUSED_ONLY[command]:
        for value in ("1e400", "nan", "9" * 400, "-1"):
            argv = [command, flag, value]
            if command == "bridge":
                argv += ["-m", SAMPLES / "uwgen.yaml", "--side", "vehicle"]
            rc, out = cli(capsys, *argv)
            assert rc == 2 and f"argument {flag}: must be" in out, (argv, out)


def test_demo_out_and_key_file_are_taken_from_the_callers_folder(tmp_path, monkeypatch):
    # The demo's child processes run in the checkout: a relative --out handed to them as
    # written made them write their records there, and a good run was reported as failed.
    from uwgen.cli import build_parser
    monkeypatch.chdir(tmp_path)
    args = build_parser("demo").parse_args(["demo", "--out", "runs/one", "--key-file", "k/net.key"])
    assert args.out == tmp_path / "runs" / "one" and args.key_file == tmp_path / "k" / "net.key"
    args = build_parser("demo").parse_args(["demo", "--out", "~/runs"])
    assert args.out == Path.home() / "runs"


def test_ros_interfaces_of_a_missing_or_empty_folder_exits_2(capsys, tmp_path):
    for folder, says in ((tmp_path / "nosuch_dir", "no such folder"), (tmp_path, "no interface package here"),
                         (tmp_path / ("d" * 5000), "cannot be looked at: File name too long")):
        rc, out = cli(capsys, "ros-interfaces", folder)
        assert rc == 2 and says in out, out


@pytest.mark.parametrize("argv, says", [
    (["keygen", "a", "b"], "uwgen keygen: error: unrecognized arguments: b"),
    (["rmw-config", "import", "t.conf", "--bogus", "-o", "x"], "uwgen rmw-config import: error: unrecognized arguments: --bogus"),
    (["analyze", "--bogus"], "uwgen analyze: error: unrecognized arguments: --bogus"),
])
def test_an_unknown_argument_is_refused_with_the_commands_own_usage(capsys, argv, says):
    rc, out = cli(capsys, *argv)
    assert rc == 2 and says in out and f"usage: uwgen {argv[0]}" in out, out


def test_rmw_config_import_takes_folders_after_its_options(capsys, tmp_path):
    conf = tmp_path / "t.conf"
    conf.write_text('{"topics": {"/pose": 3}}\n')
    out = tmp_path / "m" / "uwgen.yaml"
    rc, said = cli(capsys, "rmw-config", "import", conf, "--type", "/pose=turtlesim/msg/Pose", SAMPLES,
                   "-o", out, "--default-side", "vehicle")
    assert rc == 0 and out.is_file(), said
    assert "type: turtlesim/msg/Pose" in out.read_text()


def test_rmw_config_export_replaces_a_file_with_other_content_only_with_force(capsys, tmp_path):
    manifest = SAMPLES / "rmw_desert" / "uwgen.yaml"
    target = tmp_path / "ros_allowed_topics.conf"
    target.write_text('{"topics": {"/mine": 9}}\n')
    rc, said = cli(capsys, "rmw-config", "export", "-m", manifest, "-o", target, SAMPLES)
    assert rc == 2 and "exists with other content; pass --force" in said, said
    assert "/mine" in target.read_text()
    rc, said = cli(capsys, "rmw-config", "export", "-m", manifest, "-o", target, SAMPLES, "--force")
    assert rc == 0 and "/mine" not in target.read_text(), said
    rc, said = cli(capsys, "rmw-config", "export", "-m", manifest, "-o", target, SAMPLES)
    assert rc == 0 and "is up to date" in said, said         # the same table again: no --force needed


@pytest.mark.parametrize("command", ["analyze", "build"])
def test_an_interface_folder_with_a_name_too_long_is_a_located_error(capsys, tmp_path, command):
    folder = tmp_path / ("d" * 5000)
    argv = [command, folder, *(["-o", tmp_path / "out"] if command == "build" else ["-m", SAMPLES])]
    rc, out = cli(capsys, *argv)
    assert rc == 2 and "interface folder cannot be looked at: File name too long" in out, out[-500:]


def test_a_bridge_package_dir_with_a_name_too_long_is_a_usage_error(capsys, tmp_path):
    rc, out = cli(capsys, "bridge", "-m", SAMPLES / "uwgen.yaml", "--side", "vehicle",
                  "--package-dir", tmp_path / ("p" * 5000))
    assert rc == 2 and "not found in" in out and "(a name of 50" in out and len(out) < 1000, out[-500:]


LOG = """
import sys
from uwgen.cli import main
for name in sys.argv[1:]:
    print(main(["log", name]), flush=True)
"""


def test_log_refuses_a_device_or_a_fifo_as_a_recording_at_once(tmp_path):
    # Before: `uwgen log /dev/zero` or a FIFO never ended.
    from .helpers import bounded
    os.mkfifo(tmp_path / "run.mcap")
    res = bounded(LOG, seconds=60, argv=["/dev/zero", str(tmp_path / "run.mcap")])
    assert res.stdout.split() == ["2", "2"], res.stdout + res.stderr[-2000:]
    assert "/dev/zero is a character device" in res.stderr and "run.mcap is a FIFO" in res.stderr
