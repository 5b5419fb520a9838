"""The command-line door: any value of any number flag gives a clear usage error or a run;
never a traceback (OverflowError from 1e400 or a 400-digit number), never a run that does
not end (`uwgen emulate --nodes 100000000` built a hundred million nodes)."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from .helpers import SAMPLES, cli

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


@settings(max_examples=120, deadline=20_000,
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
