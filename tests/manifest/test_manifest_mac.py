"""The manifest's `mac:` section: modes, defaults, and every mistake located."""
from __future__ import annotations

import pytest

from uwgen.manifest.mac import mac_from_text, round_trip
from uwgen.manifest.model import MacConfig
from uwgen.manifest.nodes import ManifestError

from .helpers import SIDES, error_of, load_text

THREE = """
        network: demo
        sides:
          surface: {port: 4000}
          auv1: {port: 4001}
          auv2: {port: 4002}
"""


def test_no_mac_section_is_mode_none(tmp_path):
    assert load_text(tmp_path, SIDES).mac == MacConfig()


def test_tdma_slots_default_to_the_sides_in_order(tmp_path):
    m = load_text(tmp_path, THREE + "        mac: {mode: tdma, frame: 3.0, guard: 0.3}\n")
    assert m.mac.slots == ("surface", "auv1", "auv2")
    assert m.mac.slot == pytest.approx(1.0) and m.mac.slot_of("auv2") == 2


def test_tdma_weights_give_a_side_a_longer_slot_of_the_same_frame(tmp_path):
    m = load_text(tmp_path, THREE + "        mac: {mode: tdma, frame: 4.0, guard: 0.3, "
                  "weights: {surface: 2}}\n")
    mac = m.mac
    assert mac.slot_weights() == (2, 1, 1)
    assert [mac.slot_length(s) for s in mac.slots] == pytest.approx([2.0, 1.0, 1.0])
    assert [mac.slot_start(s) for s in mac.slots] == pytest.approx([0.0, 2.0, 3.0])
    assert mac.slot == pytest.approx(1.0)                 # the shortest


def test_turns_take_a_leader_and_packets_per_side(tmp_path):
    m = load_text(tmp_path, THREE + "        mac: {mode: turns, leader: auv1, packets: {auv2: 7}}\n")
    assert m.mac.leader == "auv1"
    assert m.mac.turn_packets("auv2") == 7 and m.mac.turn_packets("surface") == 4
    m = load_text(tmp_path, THREE + "        mac: {mode: turns, packets: 2}\n")
    assert m.mac.leader == "surface" and m.mac.turn_packets("auv1") == 2


@pytest.mark.parametrize("mac, line, column, message", [
    ("{mode: tdma, slots: [surface, vehicle, surface]}", 5, 45, "two slots"),
    ("{mode: tdma, slots: [surface]}", 5, 26, "without a slot"),
    ("{mode: tdma, slots: [surface, boat]}", 5, 36, "'boat' is not a declared side"),
    ("{mode: tdma, frame: 1.0, guard: 0.5}", 5, 38, "leaves no time to send"),
    ("{mode: tdma, frame: 1.0, guard: 0.3, weights: {surface: 3}}", 5, 38,
     "side vehicle's 0.25 s slot"),
    ("{mode: tdma, weights: {boat: 2}}", 5, 29, "'boat' has no slot"),
    ("{mode: tdma, weights: {surface: 0}}", 5, 38, "1..100"),
    ("{mode: turns, weights: {surface: 2}}", 5, 20, "belongs to mode tdma"),
    ("{mode: turns, guard: 0.5}", 5, 20, "belongs to mode tdma"),
    ("{mode: tdma, leader: surface}", 5, 19, "belongs to mode turns"),
    ("{mode: turns, leader: boat}", 5, 28, "not a declared side"),
    ("{mode: turns, packets: {vehicle: 0}}", 5, 39, "1..255"),
    ("{mode: csma}", 5, 13, "mac mode"),
])
def test_mistakes_are_located(tmp_path, mac, line, column, message):
    error = error_of(tmp_path, SIDES + f"        mac: {mac}\n")
    assert message in error.message
    assert (error.where.line, error.where.column) == (line, column)


def test_turns_on_a_wire_format_1_network_is_refused(tmp_path):
    error = error_of(tmp_path, SIDES + """
        mac: {mode: turns}
        topics:
          - {name: /chatter, id: 3, type: std_msgs/msg/String, publisher: surface, profile: rmw_desert}
        """)
    assert "wire format 4" in error.message and error.where.line == 6


def test_a_mac_given_on_the_command_line_reads_as_the_manifests():
    mac = mac_from_text("{mode: tdma, frame: 1.0, guard: 0.35, slots: [surface, vehicle]}",
                        ["surface", "vehicle"])
    assert (mac.mode, mac.frame, mac.guard, mac.slots) == ("tdma", 1.0, 0.35, ("surface", "vehicle"))
    with pytest.raises(ManifestError, match="two slots"):
        mac_from_text("{mode: tdma, slots: [a, a]}", ["a", "b"])


def test_round_trip_grows_with_what_the_mac_makes_a_reply_wait_for():
    none = round_trip(MacConfig(range=300), 0.2, 64)
    tdma = round_trip(MacConfig(mode="tdma", range=300, frame=4.0, slots=("a", "b")), 0.2, 64)
    turns = round_trip(MacConfig(mode="turns", range=300, leader="a", packets=(("a", 3), ("b", 2))),
                       0.2, 64, ["a", "b"])
    assert none < turns < tdma
    assert tdma - round_trip(MacConfig(mode="tdma", range=300, frame=1.0, slots=("a", "b")), 0.2, 64) \
        == pytest.approx(3.0)
