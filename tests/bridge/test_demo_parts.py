"""The demo's pieces that need no ROS: kinematics, the square plan, the report."""
import json
import math
import random
from pathlib import Path

import pytest

from uwgen.demo.operator import Pilot, square_waypoints
from uwgen.demo.records import Recorder, f32, read_records
from uwgen.demo.report import build_report, deviations, format_report, percentile, plot_paths
from uwgen.demo.vehicle import CMD_TIMEOUT, VehicleSim


def test_square_waypoints_close_the_square():
    wps = square_waypoints((2.0, 2.0), 4.0)
    assert wps == [(6.0, 2.0), (6.0, 6.0), (2.0, 6.0), (2.0, 2.0)]


def flight(pilot, sim, carry, until):
    """The pilot (10 Hz) and the vehicle joined by a link: `carry(t, tick, command, cmds,
    poses)` puts what the link carries at time t on `cmds` (arrival, command) and `poses`
    (arrival, pose). Returns the vehicle's path."""
    cmds, poses, path, last = [], [], [], None
    t, step = 0.0, 0.02
    while t < until and not pilot.done:
        k = round(t / step)
        if k % 5 == 0:                                    # 10 Hz operator
            last = pilot.command(t)
            if last is None:
                break
        carry(t, k, last, cmds, poses)
        while cmds and cmds[0][0] <= t:
            sim.command(*cmds.pop(0)[1], now=t)
        while poses and poses[0][0] <= t:
            pilot.observe(*poses.pop(0)[1], t)
        sim.step(t, step)
        path.append((sim.x, sim.y))
        t += step
    return path


def fly(pilot, sim, seed, cmd_delay=0.45, pose_delay=0.5, loss=0.25, until=150.0):
    """The pilot and the vehicle joined by a lossy, late link (5 Hz latest for commands,
    2 Hz for poses, as the demo manifest allows). Returns the vehicle's path."""
    rng = random.Random(seed)

    def carry(t, k, cmd, cmds, poses):
        if k % 10 == 0 and rng.random() > loss:           # link rate 5/s, some lost
            cmds.append((t + cmd_delay, cmd))
        if k % 25 == 0 and rng.random() > loss:           # pose at 2 Hz, some lost
            poses.append((t + pose_delay, (sim.x, sim.y, sim.theta)))
    return flight(pilot, sim, carry, until)


def square(link, seed) -> tuple[Pilot, float]:
    """The pilot drives the demo's square over `link` (fly, fly_in_bursts): the pilot, and
    the path's largest deviation from the square."""
    wps = square_waypoints((2.0, 2.0), 4.0)
    sim = VehicleSim(2.0, 2.0, 0.0)
    pilot = Pilot(wps)
    path = link(pilot, sim, seed)
    assert pilot.done, f"stuck at waypoint {pilot.index}"
    return pilot, max(deviations([(2.0, 2.0), *wps], path))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_pilot_drives_the_square_through_a_late_lossy_link(seed):
    _, worst = square(fly, seed)
    assert worst < 0.3, worst


def fly_in_bursts(pilot, sim, seed, loss=0.3, round_=2.5, delay=0.32, until=200.0):
    """A link of turns whose round is longer than the vehicle's command timeout: each round
    the surface's turn carries 4 commands (0.2 s apart), the vehicle's 2 poses, each packet
    lost at `loss`; the vehicle stops between the bursts."""
    rng = random.Random(seed)
    pose_phases = (int(1.12 / 0.02), int(1.32 / 0.02))

    def carry(t, k, cmd, cmds, poses):
        phase = round((t % round_) / 0.02)
        if phase in (0, 10, 20, 30) and cmd is not None and rng.random() > loss:
            cmds.append((t + delay, cmd))
        if phase in pose_phases and rng.random() > loss:
            poses.append((t + delay, (sim.x, sim.y, sim.theta)))
    return flight(pilot, sim, carry, until)


@pytest.mark.parametrize("seed", [5, 13, 21])
def test_pilot_learns_how_much_of_its_commands_act_and_turns_at_the_corners(seed):
    # counting every command in full, the pilot turned 0.9-1.0 m short of a corner on
    # these seeds: the vehicle had stopped between bursts for part of the time
    pilot, worst = square(fly_in_bursts, seed)
    assert worst < 0.5, worst
    assert pilot.share < 0.9                  # learned: less than every command acted


def test_pilot_share_follows_what_two_poses_show():
    pilot = Pilot([(10.0, 0.0)], lag=1.0)
    pilot.observe(0.0, 0.0, 0.0, t=0.0)
    for k in range(20):                       # 2 s at 0.4 m/s: 0.8 m commanded
        pilot.sent.append((k / 10, 0.4, 0.0))
    pilot.observe(0.4, 0.0, 0.0, t=3.0)       # moved half of it
    assert pilot.share == pytest.approx(0.7 * 1.0 + 0.3 * 0.5)
    pilot.observe(0.4, 0.0, 0.0, t=3.1)       # too little commanded between these two: kept
    assert pilot.share == pytest.approx(0.85)


def test_pilot_holds_at_a_corner_it_reached_only_by_prediction_until_a_pose_confirms_it():
    # as in a demo run under turns at 20 % PER: the last pose 3.9 m along the top edge, then
    # none for 4.8 s while half the commands acted; counting them all, the pilot turned for
    # the next corner 1.1 m early
    pilot = Pilot([(2.0, 6.0), (2.0, 2.0)], lag=1.0)
    pilot.observe(3.9, 6.0, math.pi, t=0.0)
    t, cmd = 0.0, (0.4, 0.0)
    while cmd != (0.0, 0.0) and t < 10.0:
        t += 0.1
        cmd = pilot.command(t)
    assert cmd == (0.0, 0.0) and pilot.index == 0 and 2.5 < t < 5.5   # reached by the guess: held
    pilot.observe(3.1, 6.0, math.pi, t=t + 0.5)                      # where it really is
    lin, _ = pilot.command(t + 0.6)
    assert lin > 0.0 and pilot.index == 0                             # on to the corner


def test_vehicle_integrates_commands_and_stops_when_they_go_stale():
    sim = VehicleSim(0.0, 0.0, 0.0)
    sim.command(1.0, 0.0, now=0.0)
    for i in range(50):
        sim.step(i * 0.02, 0.02)
    assert (sim.x, sim.y) == (pytest.approx(1.0), pytest.approx(0.0))
    x = sim.x
    for i in range(100):  # no new command: after CMD_TIMEOUT the vehicle stops
        sim.step(1.0 + CMD_TIMEOUT + i * 0.02, 0.02)
    assert sim.x == pytest.approx(x + 0.0, abs=0.03) and sim.lin == 0.0


def test_vehicle_turns_by_the_commanded_angle():
    sim = VehicleSim(0.0, 0.0, 0.0)
    sim.command(0.0, math.pi / 2, now=0.0)
    for i in range(50):
        sim.step(i * 0.02, 0.02)
    assert sim.theta == pytest.approx(math.pi / 2)


def test_percentile_interpolates():
    assert percentile([], 95) is None
    assert percentile([1.0, 2.0, 3.0, 4.0, 5.0], 50) == 3.0
    assert percentile([0.0, 10.0], 95) == pytest.approx(9.5)


def test_deviation_is_distance_to_the_commanded_polyline():
    commanded = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]
    assert deviations(commanded, [(0.5, 0.2), (1.3, 0.5)]) == [pytest.approx(0.2), pytest.approx(0.3)]


def write(path, records):
    path.write_text("\n".join(json.dumps(r) for r in records) + "\n")


def test_report_matches_messages_and_accounts_for_drops(tmp_path):
    t = 1000.0
    op = [{"t": t, "ev": "start", "x": 0.0, "y": 0.0, "theta": 0.0}]
    veh = [{"t": t, "ev": "teleport", "x": 0.0, "y": 0.0, "theta": 0.0}]
    for k in range(1, 11):
        op.append({"t": t + k * 0.1, "ev": "cmd", "k": k, "lin": 1.0, "ang": 0.0})
        if k % 2 == 0:  # half of them arrive, 0.4 s later
            veh.append({"t": t + k * 0.1 + 0.4, "ev": "cmd", "k": k, "lin": 1.0, "ang": 0.0})
    for i in range(5):
        pose = {"x": f32(i * 0.2), "y": 0.0, "theta": 0.0, "v": 1.0, "w": 0.0}
        veh.append({"t": t + i * 0.2, "ev": "pose", **pose})
        op.append({"t": t + i * 0.2 + 0.5, "ev": "pose_rx", **pose})
    op.append({"t": t + 2, "ev": "call", "name": "/vehicle/set_pen", "ok": True, "rtt": 0.8})
    op.append({"t": t + 3, "ev": "call", "name": "/vehicle/set_pen", "ok": False, "rtt": 12.0})
    op.append({"t": t + 9, "ev": "mission", "name": "/turtle1/rotate_absolute", "ok": True,
               "status": "succeeded", "feedback": 4, "rtt": 6.5, "delta": 1.25})
    write(tmp_path / "operator.jsonl", op)
    write(tmp_path / "vehicle.jsonl", veh)
    (tmp_path / "bridge_surface.json").write_text(json.dumps({"topics": {"/turtle1/cmd_vel": {
        "taken": 10, "link": {"offered": 10, "sent": 6, "superseded": 4, "queued": 0}}},
        "link": {"wire_format": 4, "connection": {"bytes_sent": 100, "writes": 10}}}))
    (tmp_path / "bridge_vehicle.json").write_text(json.dumps({"topics": {"/turtle1/cmd_vel": {
        "received": 5}}, "link": {"wire_format": 4, "connection": {"bytes_sent": 200, "writes": 5}}}))
    report = build_report(tmp_path)
    cmd = report.topics[0]
    assert (cmd.published, cmd.taken, cmd.on_link, cmd.policy, cmd.lost, cmd.delivered) == (10, 10, 6, 4, 1, 5)
    assert cmd.p50 == pytest.approx(0.4)
    pose = report.topics[1]
    assert pose.delivered == 5 and pose.p95 == pytest.approx(0.5)
    pen = report.services[0]
    assert (pen.calls, pen.ok, pen.failed) == (2, 1, 1)
    text = format_report(report)
    assert "/turtle1/cmd_vel" in text and "400 ms" in text
    assert ("action /turtle1/rotate_absolute: succeeded after 6.50 s, 4 feedback messages, "
            "turned 1.25 rad") in text
    # air: 100 + 4 x 10 and 200 + 4 x 5 bytes for 5 cmd + 5 pose + 2 (one call) + 7 (mission)
    assert report.messages_delivered == 19
    assert "air bytes per delivered message: 18.9 (19 messages" in text and "wire format 4" in text
    png = plot_paths(report, tmp_path / "p.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_recorder_writes_lines_and_reader_skips_a_torn_tail(tmp_path):
    rec = Recorder(tmp_path / "r.jsonl")
    rec("a", k=1)
    rec("b", k=2)
    rec.close()
    with (tmp_path / "r.jsonl").open("a") as fh:
        fh.write('{"t": 1, "ev": "tor')
    assert [r["k"] for r in read_records(tmp_path / "r.jsonl")] == [1, 2]


def test_a_received_message_is_recorded_when_the_far_bridge_published_it_not_when_taken(tmp_path):
    # The report's latency ends where `uwgen log`'s does (the far bridge's publication), so an
    # application's executor that takes the message late does not lengthen it.
    import time

    from std_msgs.msg import String

    from uwgen.demo.records import delivered_at

    from .harness import ros_sides
    rec = Recorder(tmp_path / "r.jsonl")
    with ros_sides("app", same_domain=True) as (app,):
        node = app.node("taker")
        pub = node.create_publisher(String, "/said", 10)
        taken = []
        node.create_subscription(String, "/said", lambda msg, info: (
            time.sleep(0.3), rec("said", at=delivered_at(info), data=msg.data), taken.append(time.time())), 10)
        deadline = time.monotonic() + 10
        while not taken and time.monotonic() < deadline:
            published = time.time()
            pub.publish(String(data="hi"))
            time.sleep(0.5)
        rec.close()
    assert taken, "the subscription never took the message"
    first = next(read_records(tmp_path / "r.jsonl"))
    assert first["ev"] == "said" and first["data"] == "hi"
    assert taken[0] - first["t"] >= 0.3                # taken 0.3 s later, recorded at its publication
    assert abs(first["t"] - published) < 0.1


def test_a_record_without_a_source_timestamp_takes_now(tmp_path):
    import time
    from uwgen.demo.records import delivered_at
    assert delivered_at({}) is None and delivered_at(None) is None
    assert delivered_at({"source_timestamp": 1_500_000_000}) == 1.5
    rec = Recorder(tmp_path / "r.jsonl")
    before = time.time()
    rec("x", at=delivered_at({"source_timestamp": 0}))
    rec("y", at=12.5)
    rec.close()
    x, y = read_records(tmp_path / "r.jsonl")
    assert x["t"] >= before and y["t"] == 12.5


def test_turn_to_gives_the_short_way_round():
    from uwgen.demo.vehicle import turn_to
    assert turn_to(1.5, 0.5) == pytest.approx(1.0)
    assert turn_to(-3.0, 3.0) == pytest.approx(2 * math.pi - 6.0)   # across +-pi, not back


def test_report_reads_the_bridges_accounting_and_names_what_does_not_add_up(tmp_path):
    write(tmp_path / "operator.jsonl", [{"t": 1.0, "ev": "start", "x": 0.0, "y": 0.0, "theta": 0.0}])
    write(tmp_path / "vehicle.jsonl", [])
    out = {"published": 12, "taken": 10, "dropped_by_subscription": 2,
           "dropped_by_policy": {"superseded": 3, "overflow": 0, "encode_error": 1}, "queued": 0, "sent": 6}
    inc = {"received": 4, "lost_on_link": 1, "delivered": 3,
           "dropped_on_receive": {"decode_error": 0, "publish_error": 0}}
    (tmp_path / "bridge_surface.json").write_text(json.dumps({"topics": {"/turtle1/cmd_vel": {
        "accounting": out}}}))
    (tmp_path / "bridge_vehicle.json").write_text(json.dumps({"topics": {"/turtle1/cmd_vel": {
        "accounting": inc}}}))
    cmd = build_report(tmp_path).topics[0]
    assert (cmd.taken, cmd.sub_dropped, cmd.on_link, cmd.policy, cmd.lost, cmd.lost_seen) == (10, 2, 6, 4, 2, 1)
    text = format_report(build_report(tmp_path))
    assert "2 (1)" in text
    assert "counters do not add up: received 4 != delivered 3 + dropped on receive 0" in text


def test_pose_key_steps_are_the_demo_manifests_pose_encodings():
    from uwgen.demo.report import POSE_KEY_STEPS
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.manifest.loader import load_manifest
    root = Path(__file__).resolve().parents[2] / "msg_samples"
    manifest = load_manifest(root / "uwgen.yaml", InterfaceLibrary([root], installed=True))
    pose = next(t for t in manifest.topics if t.name == "/turtle1/pose")
    steps = {f.path: float(f.step) for f in pose.fields}
    names = {"x": "x", "y": "y", "theta": "theta", "v": "linear_velocity", "w": "angular_velocity"}
    assert {names[k]: step for k, step in POSE_KEY_STEPS} == steps


def test_quantized_poses_still_match_their_publication(tmp_path):
    t = 1000.0
    veh, op = [], []
    for i in range(4):
        sent = {"x": f32(1.0 + i * 0.2037), "y": f32(2.0), "theta": f32(0.7854), "v": f32(0.4), "w": 0.0}
        got = {"x": round(sent["x"], 2), "y": 2.0, "theta": 0.785, "v": 0.4, "w": 0.0}   # as the grid decodes
        veh.append({"t": t + i, "ev": "pose", **sent})
        op.append({"t": t + i + 0.3, "ev": "pose_rx", **got})
    write(tmp_path / "operator.jsonl", op)
    write(tmp_path / "vehicle.jsonl", veh)
    pose = build_report(tmp_path).topics[1]
    assert pose.delivered == 4 and pose.p50 == pytest.approx(0.3)


def test_demo_report_shows_encoded_frame_sizes_next_to_native(tmp_path):
    from uwgen.demo.report import frame_sizes
    root = Path(__file__).resolve().parents[2] / "msg_samples"
    sizes = {z.topic: z for z in frame_sizes(root / "uwgen.yaml", [root])}
    assert set(sizes) == {"/turtle1/cmd_vel", "/turtle1/pose"}
    for z in sizes.values():
        assert z.sent < z.native and z.how == "packed + field encodings"
    cmd, pose = sizes["/turtle1/cmd_vel"], sizes["/turtle1/pose"]
    # wire format 2: frame, P and W, H, 9 + 16 + 9 bits of x, z (command number), yaw; then
    # the packet's tag (8), measured on a really sealed packet holding the message alone
    assert (cmd.security, cmd.security_bytes) == ("encrypt", 8)
    assert cmd.sent == 4 + 3 + 1 + 5 + 8
    assert (pose.security, pose.security_bytes) == ("sign", 8)
    write(tmp_path / "operator.jsonl", [])
    write(tmp_path / "vehicle.jsonl", [])
    report = build_report(tmp_path)
    report.sizes = list(sizes.values())
    assert (f"/turtle1/cmd_vel 21 B = 13 B with packed + field encodings + 8 B encrypt "
            f"(native, unprotected: {cmd.native} B)") in format_report(report)


def test_report_shows_each_bridges_security_counts_and_drop_reasons(tmp_path):
    write(tmp_path / "operator.jsonl", [])
    write(tmp_path / "vehicle.jsonl", [])
    counts = {"protected": 0, "sync_sent": 0, "verified": 0, "bad_tag": 0, "replay": 0, "dropped": 0}
    (tmp_path / "bridge_surface.json").write_text(json.dumps(
        {"security": {**counts, "protected": 310, "verified": 150}}))
    (tmp_path / "bridge_vehicle.json").write_text(json.dumps(
        {"security": {**counts, "protected": 151, "verified": 305, "bad_tag": 3, "replay": 1, "dropped": 4}}))
    report = build_report(tmp_path)
    assert report.security["vehicle"]["verified"] == 305
    assert ("security: surface protected 310 verified 150 dropped 0; vehicle protected 151 "
            "verified 305 dropped 4 (bad_tag 3, replay 1)") in format_report(report)


def test_report_of_an_unsecured_run_has_no_security_line(tmp_path):
    write(tmp_path / "operator.jsonl", [])
    write(tmp_path / "vehicle.jsonl", [])
    (tmp_path / "bridge_surface.json").write_text(json.dumps({"security": None}))
    report = build_report(tmp_path)
    assert report.security == {} and "security:" not in format_report(report)


def _square_report(tmp_path, mission: dict):
    """A report of a run that drove the 4 m square from (2, 2) and sent one mission goal."""
    from uwgen.demo.operator import START
    t = 1000.0
    corners = square_waypoints(START[:2], 4.0, 1)
    op = [{"t": t, "ev": "start", "x": START[0], "y": START[1], "theta": 0.0, "waypoints": corners}]
    veh = [{"t": t, "ev": "teleport", "x": START[0], "y": START[1], "theta": 0.0}]
    for i, (x, y) in enumerate(corners):
        pose = {"x": f32(x), "y": f32(y), "theta": 0.0, "v": 0.0, "w": 0.0}
        veh.append({"t": t + i, "ev": "pose", **pose})
        op.append({"t": t + i + 0.5, "ev": "pose_rx", **pose})
    op.append({"t": t + 9, "ev": "mission", "name": "/turtle1/rotate_absolute", **mission})
    write(tmp_path / "operator.jsonl", op)
    write(tmp_path / "vehicle.jsonl", veh)
    return build_report(tmp_path)


def test_an_aborted_mission_says_aborted_not_how_far_it_turned(tmp_path):
    report = _square_report(tmp_path, {"ok": False, "status": "aborted", "feedback": 2, "rtt": 4.0,
                                       "delta": 0.0})
    text = format_report(report)
    line = next(x for x in text.splitlines() if x.startswith("action "))
    assert line.startswith("action /turtle1/rotate_absolute: aborted after 4.00 s") and "turned" not in line


def test_the_report_explains_its_columns(tmp_path):
    text = format_report(_square_report(tmp_path, {"ok": True, "status": "succeeded", "feedback": 1,
                                                    "rtt": 3.0, "delta": 1.5}))
    assert "turned 1.50 rad" in text
    legend = " ".join(text.split())
    assert "sub drop: messages the sending bridge's subscription lost" in legend
    assert "lost (seen): put on the link, never received by the far bridge; (seen) of those" in legend


def test_the_plot_legend_does_not_cover_the_square(tmp_path):
    from uwgen.demo.report import path_figure
    report = _square_report(tmp_path, {"ok": True, "status": "succeeded", "feedback": 1, "rtt": 3.0,
                                       "delta": 1.5})
    fig = path_figure(report, "title")
    fig.canvas.draw()
    ax = fig.axes[0]
    box = ax.get_legend().get_window_extent()
    points = ax.transData.transform([*report.commanded, *report.reported])
    assert not [p for p in points if box.contains(*p)]
    import matplotlib.pyplot as plt
    plt.close(fig)


@pytest.mark.parametrize("given", ["0", "1", "100", "101", "150", "231", "4000"])
def test_demo_domains_are_two_different_ids_ros_advises_on_linux(monkeypatch, given):
    from uwgen.demo.processes import domains
    monkeypatch.setenv("ROS_DOMAIN_ID", given)
    vehicle, surface = domains()
    assert vehicle != surface
    assert 0 <= vehicle <= 101 and 0 <= surface <= 101


def _lost_seen(tmp_path, link: dict, received: int, receiver_seen: int):
    write(tmp_path / "operator.jsonl", [{"t": 1.0, "ev": "start", "x": 0.0, "y": 0.0, "theta": 0.0}])
    write(tmp_path / "vehicle.jsonl", [])
    out = {"published": 16, "taken": 16, "dropped_by_subscription": 0, "dropped_by_policy": {}, "queued": 0,
           "sent": 16}
    inc = {"received": received, "lost_on_link": receiver_seen, "delivered": received,
           "dropped_on_receive": {"decode_error": 0, "publish_error": 0}}
    (tmp_path / "bridge_vehicle.json").write_text(json.dumps({"topics": {"/vehicle/battery": {
        "accounting": out, "link": link}}}))
    (tmp_path / "bridge_surface.json").write_text(json.dumps({"topics": {"/vehicle/battery": {
        "accounting": inc}}}))
    row = next(r for r in build_report(tmp_path).topics if r.name == "/vehicle/battery")
    return row.lost, row.lost_seen


def test_lost_seen_counts_messages_not_the_fragments_acks_name(tmp_path):
    # 16 messages in 32 fragments: the acks name 9 fragments missing, 6 messages never completed,
    # 2 of them with some fragments received
    link = {"fragments_sent": 32, "on_link": {"sent": 32, "delivered": 23, "lost_on_link": 9,
                                              "in_flight": 0, "unacknowledged": 0}}
    lost, seen = _lost_seen(tmp_path, link, received=10, receiver_seen=2)
    assert (lost, seen) == (6, 2) and seen <= lost


def test_lost_seen_is_never_more_than_lost(tmp_path):
    # unfragmented: the acks name 8 copies missing, but 2 of them arrived after all
    link = {"fragments_sent": 0, "on_link": {"sent": 16, "delivered": 8, "lost_on_link": 8,
                                             "in_flight": 0, "unacknowledged": 0}}
    lost, seen = _lost_seen(tmp_path, link, received=10, receiver_seen=0)
    assert (lost, seen) == (6, 6)
    text = format_report(build_report(tmp_path))
    assert "6 (6)" in text and "6 (8)" not in text


@pytest.mark.parametrize("given, expected", [("21", (21, 22)), ("205", (3, 4)), ("0", (0, 1))])
def test_the_demo_uses_the_domains_its_help_and_docs_state(monkeypatch, given, expected):
    from uwgen.cli import build_parser
    from uwgen.demo.processes import domains
    monkeypatch.setenv("ROS_DOMAIN_ID", given)
    assert domains() == expected
    parser = build_parser("demo")
    demo = next(a for a in parser._subparsers._group_actions[0].choices.values() if a.prog.endswith("demo"))
    text = " ".join(demo.format_help().split())
    assert "ROS domain ROS_DOMAIN_ID (taken modulo 101" in text and "ROS_DOMAIN_ID + 1" in text
    assert "two free TCP ports" in text
    docs = " ".join((Path(__file__).resolve().parents[2] / "docs" / "demo.md").read_text().replace("`", "").split())
    assert "ROS_DOMAIN_ID (modulo 101" in docs and "ROS_DOMAIN_ID + 1" in docs


def test_the_run_shown_in_the_docs_has_the_lines_the_report_prints(tmp_path):
    # headers, rules and legends carry no figures: each the docs show is one the report prints
    doc = (Path(__file__).resolve().parents[2] / "docs" / "demo.md").read_text(encoding="utf-8")
    block = doc.split("## A run\n\n```\n", 1)[1].split("```", 1)[0].splitlines()
    text = format_report(_square_report(tmp_path, {"ok": True, "status": "succeeded", "feedback": 1,
                                                    "rtt": 3.0, "delta": 1.5}))
    printed = set(text.splitlines())
    fixed = [line for line in block if line.strip() and not any(c.isdigit() for c in line)]
    assert len(fixed) >= 5 and [line for line in fixed if line not in printed] == []
    for label in ("action /turtle1/rotate_absolute: succeeded after", "path: the poses the surface received"):
        assert any(line.startswith(label) for line in block) and any(line.startswith(label) for line in printed)


# -- the fleet demo (uwgen demo --vehicles N) ------------------------------------------------

def fleet_args(**kw):
    import argparse
    base = dict(vehicles=3, distance=300.0, per=0.05, seed=1, phy="none", mac="manifest")
    return argparse.Namespace(**{**base, **kw})


def test_the_fleet_demo_shares_the_channel_by_the_manifests_tdma_one_slot_per_side():
    from uwgen.demo.fleet import fleet_mac, scenario
    mac = fleet_mac(fleet_args())
    assert mac.mode == "tdma" and mac.slots == ("surface", "auv1", "auv2", "auv3")
    # the guard covers a packet's air time and the 300 m delay: no two slots' packets overlap
    assert mac.guard >= (64 + 4) * 8 / mac.bitrate + 300 / 1500
    scen, names, _ = scenario(fleet_args(vehicles=2))
    assert names == ["auv1", "auv2"] and scen.tdma.slots == 4
    assert [n.dest for n in scen.nodes] == ["*", "surface", "surface"]
    far = [math.dist(n.position, (0, 0, 0)) for n in scen.nodes[1:]]
    assert far == pytest.approx([300.0, 300.0])


def test_the_fleet_demo_can_take_turns_instead():
    from uwgen.demo.fleet import fleet_mac
    mac = fleet_mac(fleet_args(mac="turns"))
    assert (mac.mode, mac.leader, mac.range) == ("turns", "surface", 300.0)


def test_a_fleet_vehicle_that_did_not_follow_is_named_with_why():
    from uwgen.demo.fleet import vehicle_problems
    from uwgen.demo.report import Report, Row, ServiceRow
    cmd, pose = Row("/auv2/turtle1/cmd_vel", "surface → vehicle"), Row("/auv2/turtle1/pose", "vehicle → surface")
    cmd.delivered, pose.delivered = 40, 0
    pen = ServiceRow("/auv2/vehicle/set_pen")
    pen.calls, pen.ok = 2, 0
    report = Report([cmd, pose], [pen], [], [], [], None, 0.9, None, {}, [{"status": "succeeded"}])
    assert vehicle_problems(report) == [
        "no pose reached the surface", "every call of /auv2/vehicle/set_pen failed",
        "the reported path is not within 0.5 m of the square"]


def test_the_mac_the_demo_gives_its_bridges_is_the_manifests_weights_and_all():
    from uwgen.commands.demo import mac_text
    from uwgen.manifest.mac import mac_from_text
    from uwgen.manifest.model import MacConfig
    weighted = MacConfig(mode="tdma", frame=3.7, guard=0.34, slots=("surface", "auv1", "auv2"),
                         max_packet_per_slot=6, queue_size=10, weights=(("surface", 2),),
                         range=300)                  # the surface's slot twice as long
    assert mac_from_text(mac_text(weighted), list(weighted.slots)) == weighted


def fly_tdma(pilot, sim, seed, frame, pose_at, surface_at=0.3, writes=3, spacing=0.2,
             transit=0.3, loss=0.1, until=400.0):
    """The pilot and the vehicle over TDMA with writes timed to the slots (the fleet demo):
    in each frame the surface's slot carries the pilot's latest command at each of its
    `writes`, the vehicle's slot its pose at `pose_at` s into the frame. Returns the path."""
    rng = random.Random(seed)

    def carry(t, k, last, cmds, poses):
        phase = t % frame
        if last is not None and any(abs(phase - (surface_at + i * spacing)) < 0.01
                                    for i in range(writes)) and rng.random() > loss:
            cmds.append((t + transit, last))
        if abs(phase - pose_at) < 0.01 and rng.random() > loss:
            poses.append((t + transit, (sim.x, sim.y, sim.theta)))
    return flight(pilot, sim, carry, until)


@pytest.mark.parametrize("pose_at", [0.9, 1.6, 2.4])
@pytest.mark.parametrize("seed", [1, 4, 7])
def test_pilot_finishes_the_square_over_tdma_wherever_the_vehicles_slot_is(seed, pose_at):
    # the fleet demo's pilot settings: a 3.1 s frame, commands counted as fleet.lag says; a
    # vehicle whose slot comes late sends a pose that already shows the frame's commands
    from types import SimpleNamespace

    from uwgen.demo.fleet import lag
    frame = 3.1
    wps = square_waypoints((2.0, 2.0), 1.0)
    sim = VehicleSim(2.0, 2.0, 0.0)
    pilot = Pilot(wps, speed=0.3, turn=0.5, lag=lag(SimpleNamespace(mode="tdma", frame=frame), 3),
                  share=min(1.0, CMD_TIMEOUT / frame))
    path = fly_tdma(pilot, sim, seed, frame, pose_at)
    assert pilot.done, f"stuck at waypoint {pilot.index}"
    assert max(deviations([(2.0, 2.0), *wps], path)) < 0.5
