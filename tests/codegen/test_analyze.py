"""`uwgen analyze`: its sizes are the sizes the codecs produce, and the link budget warns
when the configured traffic cannot fit."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from geometry_msgs.msg import Twist

from uwgen.runtime.wire.envelope import from_v1, strip_packed_head
from uwgen.analyze import air_time, analyze
from uwgen.codegen import generate
from uwgen.idl.loader import InterfaceLibrary
from uwgen.manifest.loader import load_manifest
from uwgen.manifest.model import MacConfig

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"

TIGHT = """
network: tight
sides:
  surface: {port: 4000, link: {max_read_length: 8, period: 1.0}}
  vehicle: {port: 4001}
topics:
  - name: /cmd_vel
    queue: fifo
    id: 4
    type: geometry_msgs/msg/Twist
    publisher: surface
    rate: 5
"""


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "uwgen.cli", "analyze", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT, timeout=60, env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.fixture(scope="module")
def demo():
    lib = InterfaceLibrary([SAMPLES], installed=True)
    manifest = load_manifest(SAMPLES / "uwgen.yaml", lib)
    return manifest, analyze(manifest, lib.get, 4800.0)


@pytest.fixture(scope="module")
def demo_pkg(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("an"), "uwgen_analyze_demo", folders=[SAMPLES],
                    manifest=SAMPLES / "uwgen.yaml", names=["geometry_msgs/msg/Twist"])


def on_air(payload: bytes, packed: bool = False) -> int:
    """Bytes of a generated codec's payload as a message of a wire format 2 envelope."""
    return from_v1(strip_packed_head(payload) if packed else payload).size()


def entry(analysis, kind, name):
    return next(e for e in analysis.entries if e.kind == kind and e.name == name)


def test_packed_sizes_are_what_the_codec_sends(demo, demo_pkg):
    _manifest, a = demo
    cmd = entry(a, "topic", "/turtle1/cmd_vel").configured
    assert cmd.label == "packed + fields" and cmd.payload.min == cmd.payload.max
    t = Twist()
    t.linear.x, t.linear.z, t.angular.z = 0.4, 1234.0, -0.3
    assert on_air(demo_pkg.TOPICS[4].encode(t), packed=True) == cmd.payload.typical == 6
    pose = entry(a, "topic", "/turtle1/pose").configured
    p = demo_pkg.TOPICS[5].codec.plain_class()(x=5.5, y=7.1, theta=1.2, linear_velocity=0.4, angular_velocity=0.1)
    assert on_air(demo_pkg.TOPICS[5].encode(p), packed=True) == pose.payload.typical == 8


def test_native_typical_and_worst_bracket_real_messages(demo, demo_pkg):
    _manifest, a = demo
    native = next(p for p in entry(a, "topic", "/turtle1/cmd_vel").profiles if p.label == "native")
    codec = demo_pkg.codec("geometry_msgs/msg/Twist", "native")
    t = Twist()
    t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = 0.4, 0.1, 0.7, 0.2, 0.9, 0.3
    assert on_air(codec.encode(t, [0, 4])) == native.payload.typical == native.payload.max == 55
    assert on_air(codec.encode(Twist(), [0, 4])) == native.payload.min == 19


def test_field_bits_are_listed_per_field(demo):
    _manifest, a = demo
    bits = {f.path: f.bits.max for f in entry(a, "topic", "/turtle1/cmd_vel").fields}
    assert bits == {"linear.x": 9, "linear.y": 0, "linear.z": 16, "angular.x": 0, "angular.y": 0, "angular.z": 10}


def test_demo_budget_fits_but_warns_about_entries_without_rate(demo):
    manifest, _ = demo
    # the link alone (mac none); under the demo's turns, see the test below
    lib = InterfaceLibrary([SAMPLES], installed=True)
    a = analyze(replace(manifest, mac=MacConfig()), lib.get, 4800.0)
    surface = next(b for b in a.budgets if b.side == "surface")
    # 5 cmd_vel messages of 6 bytes per second, each alone in a packet (+ 1 short frame, + 3 P
    # and W: 10), each packet 8 bytes more sealed (the tag, wire format section 12.2), plus the
    # schema announcement of the 7 ids every 600 s. Its 47 bytes (00 18 F9 00, then id + 44 +
    # 4 bytes each, id 30 taking 2 bytes) would not leave whole in one sealed 64-byte packet
    # (room 58, up to 23 of it the seal's: 35), so it is split as the bridge splits it:
    # payloads of 34 and 17 bytes, messages of 33 and 16 behind H 00 F9, + 7 alone, + 8
    # sealed: 45 and 28. The action's goals have no rate: warned about below.
    assert a.wire_format == 4          # the envelope of wire format section 14
    assert surface.schema == pytest.approx((45 + 28) / 600)
    assert surface.capacity == 320.0 and surface.typical == pytest.approx(5 * (10 + 8) + (45 + 28) / 600)
    assert any("/vehicle/log has no rate limit" in w for w in a.warnings())
    assert not any("cannot fit" in w for w in a.warnings())


def test_the_budget_under_turns_is_each_sides_turn_per_round(demo):
    manifest, a = demo
    assert manifest.mac.mode == "turns"
    surface, vehicle = (next(b for b in a.budgets if b.side == s) for s in ("surface", "vehicle"))
    assert surface.limited_by == vehicle.limited_by == "turns"
    # one round: the surface's 2 and the vehicle's 2 packets, 1.05 periods apart, and the
    # vehicle's turn round trip (twice: a period tick, 68 bytes at 4800 bit/s, 300 m, listen)
    cycle = 4 * 0.21 + 2 * (0.2 + 68 * 8 / 4800 + 0.2 + 0.05)
    assert surface.capacity == pytest.approx(2 * 64 / cycle)
    assert vehicle.capacity == pytest.approx(2 * 64 / cycle)
    assert any("side surface: topic /turtle1/cmd_vel (latest) counted at" in w for w in a.warnings())


def test_a_latest_topic_is_counted_at_most_once_a_packet_its_side_sends(demo):
    manifest, a = demo
    surface = next(b for b in a.budgets if b.side == "surface")
    cmd_vel = next(e for e in a.entries if e.name == "/turtle1/cmd_vel")
    packets = surface.capacity / manifest.sides["surface"].link.max_read_length
    assert cmd_vel.rate == 5 and packets < 5
    # under turns the surface sends about 1.1 packets a second, and cmd_vel's latest queue
    # supersedes the rest: the budget counts what can leave, and says so
    assert surface.typical == pytest.approx(surface.schema + packets * cmd_vel.configured.frame.typical)
    assert any("/turtle1/cmd_vel (latest) counted at" in line for line in surface.thinned)
    unthinned = analyze(replace(manifest, mac=MacConfig()), InterfaceLibrary([SAMPLES]).get, 4800.0)
    assert not any(b.thinned for b in unthinned.budgets)      # 5 packets/s: nothing superseded


def test_mac_warnings_name_the_guard_and_the_deadline_that_cannot_fit(tmp_path):
    lib = InterfaceLibrary([SAMPLES], installed=True)
    (tmp_path / "uwgen.yaml").write_text(TIGHT.replace("  vehicle: {port: 4001}\n", """  vehicle: {port: 4001}
mac: {mode: tdma, frame: 4.0, guard: 0.1, range: 1500}
services:
  - {name: /enable, id: 20, type: std_srvs/srv/SetBool, server: vehicle, timeout: 2}
"""))
    a = analyze(load_manifest(tmp_path / "uwgen.yaml", lib), lib.get, 4800.0)
    warnings = "\n".join(a.warnings())
    assert "guard 0.1 s is shorter than a 64-byte packet's air time plus the 1500 m range" in warnings
    assert "service /enable: its timeout 2 s cannot fit one round trip under mac tdma" in warnings


# TIGHT's link at the floor of an unsecured wire format 2 network (uwgen.linkfloor: 24 bytes),
# still 8 bytes a second: the command line refuses 8, below that floor
TIGHT_AT_FLOOR = TIGHT.replace("max_read_length: 8, period: 1.0", "max_read_length: 24, period: 3.0")


def test_traffic_that_cannot_fit_is_a_clear_warning_and_strict_fails(tmp_path):
    (tmp_path / "uwgen.yaml").write_text(TIGHT_AT_FLOOR)
    res = run_cli("-m", tmp_path / "uwgen.yaml", "--strict")
    assert res.returncode == 1, res.stderr
    assert "WARNING: side surface: configured traffic needs 295.0 B/s" in res.stdout   # 5/s x 59-byte packets
    assert "DOES NOT FIT" in res.stdout


def test_json_output_for_tools(tmp_path):
    (tmp_path / "uwgen.yaml").write_text(TIGHT_AT_FLOOR)
    res = run_cli("-m", tmp_path / "uwgen.yaml", "--json", "--bitrate", "200")
    data = json.loads(res.stdout)
    assert data["bitrate"] == 200.0
    (cmd,) = data["entries"]
    assert cmd["name"] == "/cmd_vel" and {p["label"] for p in cmd["profiles"]} == {"native", "packed"}
    assert data["budgets"][0]["capacity"] == 8.0 and data["warnings"]


def test_a_broken_manifest_is_a_located_error(tmp_path):
    (tmp_path / "uwgen.yaml").write_text(TIGHT.replace("rate: 5", "rate: 5\n    fields: {linear.w: {static: 0}}"))
    res = run_cli("-m", tmp_path / "uwgen.yaml")
    assert res.returncode == 2
    assert "uwgen.yaml:13:14:" in res.stderr and "has no field 'w'" in res.stderr


def test_air_time_counts_desert_packet_overhead():
    assert air_time(20, 200.0, 64) == pytest.approx((20 + 4) * 8 / 200)
    assert air_time(130, 4800.0, 64) == pytest.approx((130 + 3 * 4) * 8 / 4800)


def test_an_action_costs_its_goal_result_and_feedback(demo, demo_pkg):
    _manifest, a = demo
    name = "/turtle1/rotate_absolute"                  # id 30, RotateAbsolute: one float32 each
    goal, result, feedback = (entry(a, kind, name) for kind in ("goal", "result", "feedback"))
    assert (goal.sender, result.sender, feedback.sender, feedback.rate) == ("*", "vehicle", "vehicle", 1.0)
    # What the generated codec sends: 02 18 1E h, then the float32 as half (3) or single (5);
    # in the envelope H (id 30 fits it), h, the float
    codec = demo_pkg.ACTIONS[30]
    Goal, Result = codec.goal.plain_class(), codec.result.plain_class()
    goals = [on_air(codec.encode_goal(7, Goal(theta=t))) for t in (1.5, 0.1)]
    results = [on_air(codec.encode_result(7, 4, Result(delta=d))) for d in (1.5, 0.1)]
    assert (goal.configured.payload.min, goal.configured.payload.max) == tuple(goals) == (5, 7)
    assert (result.configured.payload.min, result.configured.payload.max) == tuple(results) == (6, 8)
    assert [p.label for p in goal.profiles] == ["native"]                              # native only
    vehicle = next(b for b in a.budgets if b.side == "vehicle")
    surface = next(b for b in a.budgets if b.side == "surface")
    assert f"result {name}" in vehicle.unlimited and f"goal {name}" in surface.unlimited
    assert f"feedback {name}" not in vehicle.unlimited



UWGEN = Path(sys.executable).parent / "uwgen"
SLOW_MODEM = """
network: slow
sides:
  surface: {port: 4000, link: {max_read_length: 64, period: 0.2}}
  vehicle: {port: 4001, link: {max_read_length: 64, period: 0.2}}
topics:
  - name: /depth
    queue: fifo
    id: 4
    type: std_msgs/msg/Float64
    publisher: surface
    rate: 5
"""


def test_capacity_is_limited_by_the_bit_rate_as_well_as_by_the_period(tmp_path):
    # 64 B every 0.2 s is 320 B/s, but a 200 bit/s modem carries 25 B/s, 64 of every 68
    # of them payload (DESERT adds 4 bytes per packet): 23.5 B/s. Five 14-byte packets a
    # second (wire format 4: the 10-byte message, 3 bytes of P and W and the 1-byte short
    # frame; each 0.72 s on the air) cannot fit.
    (tmp_path / "uwgen.yaml").write_text(SLOW_MODEM)
    res = subprocess.run([str(UWGEN), "analyze", "-m", str(tmp_path / "uwgen.yaml"), "--bitrate", "200",
                          "--strict"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 1, res.stdout + res.stderr
    surface = next(line.split() for line in res.stdout.splitlines() if line.startswith("  surface "))
    assert surface == ["surface", "23.5", "bit", "rate", "70.0", "70.0", "DOES", "NOT", "FIT"]
    assert "200 bit/s" in res.stdout
    fast = subprocess.run([str(UWGEN), "analyze", "-m", str(tmp_path / "uwgen.yaml"), "--strict"],
                          capture_output=True, text=True, timeout=60)
    assert fast.returncode == 0, fast.stdout + fast.stderr     # 4800 bit/s: 320 B/s by the period


def test_the_budget_says_what_limits_each_side(tmp_path):
    (tmp_path / "uwgen.yaml").write_text(SLOW_MODEM)
    lib = InterfaceLibrary([], installed=True)
    manifest = load_manifest(tmp_path / "uwgen.yaml", lib)
    slow = analyze(manifest, lib.get, 200.0).budgets[0]
    assert slow.capacity == pytest.approx(200 / 8 * 64 / 68) and slow.limited_by == "bit rate"
    fast = analyze(manifest, lib.get, 4800.0).budgets[0]
    assert fast.capacity == 320.0 and fast.limited_by == "period"


# -- control traffic: discovery beacons and schema announcements ---------------------------

def test_schema_announcements_each_fit_one_packet_and_their_air_time_is_listed(demo):
    manifest, a = demo
    for side in a.control:
        items = [i for i in side.items if i.what.startswith("schema announcement")]
        assert items and all(i.packets == 1 and i.written <= side.max_read_length for i in items)
        assert side.air == pytest.approx(sum(air_time(i.written, 4800.0, 64) for i in side.items))
    # every id of the manifest is announced once, over as few packets as the link allows
    from uwgen.bridge.schema import decode_announcement, encode_announcements
    from uwgen.analyze_control import whole_payload
    ids = {e.id for e in (*manifest.topics, *manifest.services, *manifest.actions)}
    from uwgen.security.packet_seal import max_overhead
    payloads = encode_announcements(manifest.schema_id, [(i, bytes(4)) for i in ids], True,
                                    whole_payload(2, 64, max_overhead(manifest.security.tag_bytes)))
    assert sorted(i for p in payloads for i, _ in decode_announcement(p, manifest.schema_id).pairs) == sorted(ids)
    assert len(payloads) == len(a.control[0].items)


def test_rmw_desert_beacons_are_listed_with_their_packets_echo_and_a_note():
    from uwgen.interop.beacons import encode_beacon
    from uwgen.interop.discovery import bridge_beacons
    lib = InterfaceLibrary([SAMPLES], installed=True)
    manifest = load_manifest(SAMPLES / "rmw_desert" / "uwgen.yaml", lib)
    a = analyze(manifest, lib.get, 4800.0)
    surface = next(s for s in a.control if s.side == "surface")
    beacons = [i for i in surface.items if i.what.startswith("beacon")]
    sent = [encode_beacon(b) for b in bridge_beacons(manifest, "surface")]
    assert [i.payload for i in beacons] == [len(p) for p in sent]
    for i, p in zip(beacons, sent):
        frame = len(p) + 4
        assert i.packets == -(-frame // 64) == 2
        assert i.written == frame + (frame - 64)          # the tail goes twice (its echo)
    assert surface.items[0].what == "discovery request" and surface.items[0].written == 6
    assert any("/turtle1/cmd_vel" in n and "echo" in n for n in surface.notes())
    res = run_cli("-m", SAMPLES / "rmw_desert" / "uwgen.yaml", SAMPLES)
    assert "beacon publisher /turtle1/cmd_vel" in res.stdout and "note: side surface" in res.stdout
    data = json.loads(run_cli("-m", SAMPLES / "rmw_desert" / "uwgen.yaml", SAMPLES, "--json").stdout)
    assert data["control"][0]["items"][1]["packets"] == 2


# -- fleets: one budget row per vehicle ----------------------------------------------------

def test_a_fleet_gets_a_budget_per_vehicle_and_the_surface_pays_for_every_vehicles_commands():
    lib = InterfaceLibrary([SAMPLES], installed=True)
    manifest = load_manifest(SAMPLES / "fleet" / "uwgen.yaml", lib)
    a = analyze(manifest, lib.get, 4800.0)
    rows = {b.side: b for b in a.budgets}
    assert list(rows) == ["surface", "auv1", "auv2", "auv3"]
    one = {e.name: e for e in a.entries}
    packets = rows["surface"].capacity / manifest.sides["surface"].link.max_read_length
    cmd = sum(min(packets, one[f"/auv{n}/turtle1/cmd_vel"].rate)        # latest: once a packet at most
              * one[f"/auv{n}/turtle1/cmd_vel"].configured.frame.typical for n in (1, 2, 3))
    pose = one["/auv1/turtle1/pose"]
    # the surface sends three vehicles' commands; a vehicle sends its own pose, never another's
    assert rows["surface"].typical > cmd > 0
    assert pose.rate * pose.configured.frame.typical < rows["auv1"].typical < cmd
    assert rows["auv1"].typical == pytest.approx(rows["auv2"].typical)
    # each vehicle announces its own 5 ids, the surface all 15
    control = {c.side: c for c in a.control}
    announced = lambda side: sum(i.payload for i in control[side].items if i.what.startswith("schema"))  # noqa: E731
    assert announced("surface") > 2 * announced("auv1")
