"""max_read_length has a floor: what one packet of the network must hold (frame, envelope,
reliability parts, the seal on a secured link, and the smallest fragment). Below it the
bridge ended in a ValueError traceback (every value below 47 with security on); build,
analyze and emulate now refuse it at the side that says it, and the bridge with exit 2."""
from __future__ import annotations

import re

import pytest

from uwgen.linkfloor import min_read_length
from uwgen.runtime.link.mac import TurnMac
from uwgen.runtime.delivery.reliability import OVERHEAD as RELIABILITY
from uwgen.runtime.link.packets import envelope_room
from uwgen.runtime.wire.fragment import MIN_COMPACT_PAYLOAD
from uwgen.security.keys import write_key_file
from uwgen.security.packet_seal import max_overhead

from .helpers import SAMPLES, cli

DEMO = (SAMPLES / "uwgen.yaml").read_text()
SURFACE_LINK = "    link: {max_read_length: 64, period: 0.2}"


@pytest.mark.parametrize("tag", [None, 4, 6, 8])
def test_the_floor_is_the_least_packet_whose_room_takes_the_smallest_fragment(tag):
    # The link gives its fragmenter envelope_room(max_read_length, hooks' overhead) - 1 bytes
    # (uwgen.runtime.link.link) and the fragmenter needs MIN_COMPACT_PAYLOAD of them.
    hooks = RELIABILITY + (max_overhead(tag) if tag else 0)
    floor = min_read_length(2, tag)
    assert envelope_room(floor, hooks) - 1 == MIN_COMPACT_PAYLOAD
    assert envelope_room(floor - 1, hooks) - 1 < MIN_COMPACT_PAYLOAD


def test_a_wire_format_1_link_works_from_one_byte_up():
    assert min_read_length(1, 8) == 1 == min_read_length(1, None)


# The demo network's floor: sealed with 8-byte tags (47), and its turns' C items (3 more).
DEMO_FLOOR = min_read_length(2, 8, TurnMac.overhead)


def demo_with(tmp_path, max_read_length: int):
    path = tmp_path / "uwgen.yaml"
    path.write_text(DEMO.replace(SURFACE_LINK, SURFACE_LINK.replace("64", str(max_read_length)), 1))
    (tmp_path / "turtlesim").symlink_to(SAMPLES / "turtlesim")     # the interfaces beside it
    line = DEMO[:DEMO.index(SURFACE_LINK)].count("\n") + 1
    return path, line - 2          # located at the side's entry (its `port:` line)


@pytest.mark.parametrize("value", [1, 32, DEMO_FLOOR - 1])
def test_build_analyze_and_emulate_refuse_a_max_read_length_below_the_floor_at_the_side(tmp_path, capsys, value):
    path, line = demo_with(tmp_path, value)
    for argv in (["build", "-m", path, "-o", tmp_path / "out", SAMPLES], ["analyze", "-m", path, SAMPLES],
                 ["emulate", "-m", path, "--duration", "0.05"]):
        rc, out = cli(capsys, *argv)
        assert rc == 2 and re.search(rf"{re.escape(str(path))}:{line}:\d+: max_read_length {value} of side "
                                     rf"'surface' is too small for this network: at least {DEMO_FLOOR} \(", out), (argv, out)
        assert "Traceback" not in out


def test_the_floor_itself_builds(tmp_path, capsys):
    path, _ = demo_with(tmp_path, DEMO_FLOOR)
    rc, out = cli(capsys, "build", "-m", path, "-o", tmp_path / "out", SAMPLES)
    assert rc == 0, out


@pytest.mark.parametrize("value", ["1", "32", str(DEMO_FLOOR - 1)])
def test_the_bridge_refuses_a_max_read_length_below_the_floor_with_exit_2(tmp_path, capsys, value):
    key = tmp_path / "net.key"
    write_key_file(key)
    rc, out = cli(capsys, "bridge", "-m", SAMPLES / "uwgen.yaml", "--side", "vehicle", "--port", "9",
                  "--key-file", key, "--max-read-length", value)
    assert rc == 2 and f"max_read_length {value} must be {DEMO_FLOOR}..4096 on this network" in out, out
    assert "the seal's 23 (its tag of 8)" in out and "Traceback" not in out


def test_the_manifest_reference_states_the_floors_uwgen_computes():
    text = (SAMPLES / "manifest-reference.yaml").read_text()
    plain, tag8 = min_read_length(2, None), min_read_length(2, 8)
    assert f"# the smallest fragment): {plain}, or {plain} + {max_overhead(0)} + tag_bytes with security on" in text
    assert f"({tag8} with the" in text and tag8 == plain + max_overhead(0) + 8
