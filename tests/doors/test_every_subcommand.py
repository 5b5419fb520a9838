"""Every subcommand's arguments: any mix of its own options, with hostile values (numbers of
400 digits, special files behind input names, 5 000-character names, junk words), gives a
usage error (exit 2), a failure it explains (exit 1) or a run; never a traceback, never a
hang. Commands that run for minutes when their input is good (bridge, demo) are checked up to
the end of their argument reading; the rest run (emulate with a short --duration)."""
from __future__ import annotations

import argparse
import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.cli import build_parser, parse
from uwgen.commands.options import all_parsers

from .helpers import SAMPLES, cli, examples

# Options whose value is a place uwgen writes to: given only fresh names in the test's folder
# (a FIFO there would block the writer, and /dev/zero must never be replaced).
WRITES = {"-o", "--out", "--output", "--plot", "--stats-file", "--cache", "--security-state", "path"}
NUMBERS = ["0", "-1", "1e400", "nan", "9" * 400, "4096", "47", "1", "0x10", "1_000", "+5", "1:30", ""]
WORDS = ["vehicle", "surface", "a=b", "/chatter=std_msgs/msg/String", "rmw_desert", "native", "x" * 5000,
         "-", "--", "é", "\x7f", "none"]
RUNS_LONG = ("bridge", "demo")


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    """Names that lead to every kind of file an input option must refuse or read safely."""
    d = tmp_path_factory.mktemp("places")
    os.mkfifo(d / "fifo")
    os.symlink(d / "loop-b", d / "loop-a")
    os.symlink(d / "loop-a", d / "loop-b")
    os.symlink("/dev/zero", d / "zero")
    (d / "empty").write_text("")
    (d / "junk").write_bytes(b"\xff\xfe{[: \x00")
    return [str(d / n) for n in ("fifo", "loop-a", "zero", "empty", "junk", "nosuch")] + [
        "/dev/urandom", "/dev/null", str(d), str(d / ("n" * 5000)), str(SAMPLES), str(SAMPLES / "uwgen.yaml"),
        str(SAMPLES / "rmw_desert" / "uwgen.yaml"), str(SAMPLES / "scenarios")]


def commands() -> dict[str, argparse.ArgumentParser]:
    found = {}
    for p in all_parsers(build_parser()):
        words = p.prog.split()[1:]
        if words and not any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
            found[" ".join(words)] = p
    return found


COMMANDS = commands()


def test_every_subcommand_is_fuzzed():
    assert set(COMMANDS) == {"build", "analyze", "emulate", "bridge", "demo", "ros-interfaces", "keygen", "log",
                             "rmw-config export", "rmw-config import", "rmw-config beacons"}


@st.composite
def command_line(draw, places, out_dir):
    name = draw(st.sampled_from(sorted(COMMANDS)))
    parser = COMMANDS[name]
    # --ros builds rclpy's type support of the folders (a minute or two, by design): its door
    # is the folders', drawn for ros-interfaces and build alike.
    actions = [a for a in parser._actions if a.dest not in ("help", "ros_args", "ros")]
    argv = name.split()
    fresh = iter(range(1000))

    def value(action) -> str:
        key = next(iter(action.option_strings), action.dest)
        if key in WRITES:
            return str(out_dir / f"w{next(fresh)}-{draw(st.integers(0, 10 ** 6))}")
        kind = getattr(action.type, "__name__", "")
        if kind in ("number", "whole number", "int", "float"):
            return draw(st.sampled_from(NUMBERS) | st.integers().map(str) | st.floats().map(repr))
        return draw(st.sampled_from(places + WORDS + NUMBERS))

    for action in draw(st.lists(st.sampled_from(actions), max_size=5)):
        if action.option_strings:
            argv.append(draw(st.sampled_from(action.option_strings)))
            if action.nargs == 0:
                continue
            count = draw(st.integers(1, 2)) if action.nargs in ("+", "*") else 1
            argv += [value(action) for _ in range(count)]
        else:
            argv.append(value(action))
    if name == "emulate":
        argv += ["--duration", "0.05"]
    if name == "ros-interfaces":        # never a real type support build (minutes) here
        argv = [a for a in argv if a not in (str(SAMPLES),)]
    return argv


@settings(max_examples=examples(150), deadline=30_000,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_any_arguments_of_any_subcommand_give_a_usage_error_a_failure_or_a_run(capsys, tmp_path, places, data):
    argv = data.draw(command_line(places, tmp_path))
    if argv[0] in RUNS_LONG:
        try:
            parse(build_parser(argv[0]), argv)
        except SystemExit as exc:
            assert exc.code in (0, 2), argv
        out = capsys.readouterr()
        assert "Traceback" not in out.err
        return
    if argv[0] == "emulate" and "--pdr-sweep" in argv:
        argv += ["--packets", "20"]
    if argv[0] == "build" and not {"-o", "--out", "--check"} & set(argv):
        argv += ["-o", str(tmp_path / "built")]     # never into the checkout's generated/
    rc, out = cli(capsys, *argv)
    assert rc in (0, 1, 2), (argv, rc, out[-2000:])
    assert "Traceback" not in out
    if rc == 2:
        assert "uwgen" in out and len(out) < 20_000, (argv, out[-2000:])
