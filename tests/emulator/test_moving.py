"""Moving nodes: waypoints in the scenario, live positions, and the ROS pose feed."""
from __future__ import annotations

import textwrap

import pytest

from uwgen.emulator import EmulatorCore, NodeSpec, Scenario, ScenarioError, SnrModel, \
    load_scenario
from uwgen.emulator.motion import PoseFeed, Track, position_from_msg

from .helpers import fast_link, wait_for

AIR_64 = 68 * 8 / 4800


def away(speed: float, start: float = 300.0, until: float = 200.0, **kw) -> Scenario:
    """a fixed at the origin; b starts `start` m away and moves off along x at `speed` m/s."""
    kw.setdefault("listen_jitter", 0.0)
    end = start + speed * until
    return Scenario(nodes=[NodeSpec("a", dest="b"),
                           NodeSpec("b", dest="a", waypoints=((0.0, start, 0.0, 0.0),
                                                             (until, end, 0.0, 0.0)))],
                    period=0.2, bitrate=4800.0, **kw)


def test_a_track_interpolates_between_waypoints_and_holds_at_its_ends():
    tr = Track(((10.0, 0.0, 0.0, 0.0), (20.0, 100.0, 50.0, -10.0), (30.0, 100.0, 50.0, -10.0)))
    assert tr.at(0.0) == (0.0, 0.0, 0.0)
    assert tr.at(15.0) == pytest.approx((50.0, 25.0, -5.0))
    assert tr.at(25.0) == pytest.approx((100.0, 50.0, -10.0))
    assert tr.at(99.0) == (100.0, 50.0, -10.0)


def test_propagation_delay_follows_the_distance_at_each_packet():
    scen = away(speed=50.0)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    for k in range(50):                      # one packet every 2 s, 100 m further each time
        core.client_data("a", 2.0 * k + 0.05, bytes(64))
    out = core.run_until_idle()
    assert len(out) == 50
    for d in out:
        distance = 300.0 + 50.0 * d.sent_at
        assert d.time - d.sent_at == pytest.approx(AIR_64 + distance / 1500.0, abs=1e-9)
    assert out[-1].time - out[-1].sent_at > out[0].time - out[0].sent_at + 3.0


def test_the_link_fades_as_the_vehicle_drives_away():
    # Default SNR model, wind 0: full delivery to ~7 km, nothing beyond ~8.5 km.
    scen = away(speed=100.0, until=100.0, snr=SnrModel())      # 0.3 km -> 10.3 km
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    for k in range(200):
        core.client_data("a", 0.5 * k + 0.05, bytes(32))
    out = core.run_until_idle()
    sent_at = sorted(d.sent_at for d in out)
    near = sum(1 for t in sent_at if t < 60.0)                   # under 6.3 km
    assert near == 120                                           # every packet
    assert not [t for t in sent_at if t > 85.0]                  # none beyond 8.8 km
    assert core.counters("b")["lost_snr"] == 200 - len(out)


def test_a_live_position_overrides_the_waypoints_from_then_on():
    core = EmulatorCore(away(speed=0.0))                         # b parked at 300 m
    core.client_attached("b", 0.0)
    core.client_data("a", 0.05, bytes(64))
    (first,) = core.advance(1.0)
    core.set_position("b", 1.0, (3000.0, 0.0, 0.0))
    core.client_data("a", 1.05, bytes(64))
    (second,) = core.run_until_idle()
    assert first.time - first.sent_at == pytest.approx(AIR_64 + 0.2)
    assert second.time - second.sent_at == pytest.approx(AIR_64 + 2.0)
    assert core.position("b") == (3000.0, 0.0, 0.0)


def test_a_live_position_must_be_finite():
    core = EmulatorCore(away(speed=0.0))
    with pytest.raises(ValueError, match="finite"):
        core.set_position("b", 0.0, (float("nan"), 0.0, 0.0))


def test_waypoints_and_pose_topic_load_from_yaml(tmp_path):
    path = tmp_path / "moving.yaml"
    path.write_text(textwrap.dedent("""\
        nodes:
          - name: surface
          - name: auv
            waypoints: [[0, 300, 0, 50], [60, 3300, 0, 50]]
          - name: glider
            pose_topic: {topic: /glider/odom, type: nav_msgs/msg/Odometry, scale: 100,
                         offset: [10, 20]}
        """))
    scen = load_scenario(path)
    assert scen.position_at("auv", 30.0) == pytest.approx((1800.0, 0.0, 50.0))
    feed = scen.node("glider").pose_topic
    assert feed == PoseFeed("/glider/odom", "nav_msgs/msg/Odometry", 100.0, (10.0, 20.0, 0.0))
    assert feed.to_position((1.0, 2.0, 3.0)) == (110.0, 220.0, 300.0)
    assert scen.moves("auv") and scen.moves("glider") and not scen.moves("surface")


@pytest.mark.parametrize("waypoints, message", [
    ("[[0, 1, 2]]", "four numbers"),
    ("[[5, 0, 0, 0], [5, 1, 0, 0]]", "times must increase"),
    ("[[-1, 0, 0, 0]]", "time must be >= 0"),
    ("[]", "non-empty"),
])
def test_bad_waypoints_are_reported_at_their_line(tmp_path, waypoints, message):
    path = tmp_path / "bad.yaml"
    path.write_text(f"nodes:\n  - name: a\n  - name: b\n    waypoints: {waypoints}\n")
    with pytest.raises(ScenarioError, match=message) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}:4:")


def test_a_bad_pose_topic_is_reported(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("nodes:\n  - name: a\n  - name: b\n    pose_topic: {topic: odom}\n")
    with pytest.raises(ScenarioError, match="absolute ROS name"):
        load_scenario(path)


def test_positions_are_read_from_real_ros_pose_messages():
    from geometry_msgs.msg import Point, Pose, PoseStamped
    from nav_msgs.msg import Odometry

    odom = Odometry()
    odom.pose.pose.position = Point(x=1.0, y=2.0, z=3.0)
    stamped = PoseStamped()
    stamped.pose.position = Point(x=4.0, y=5.0, z=6.0)
    assert position_from_msg(odom) == (1.0, 2.0, 3.0)
    assert position_from_msg(stamped) == (4.0, 5.0, 6.0)
    assert position_from_msg(Pose(position=Point(x=7.0, y=8.0))) == (7.0, 8.0, 0.0)
    assert position_from_msg(Point(x=9.0, y=1.0, z=2.0)) == (9.0, 1.0, 2.0)
    from std_msgs.msg import String
    with pytest.raises(ValueError, match="no position"):
        position_from_msg(String(data="x"))


def test_a_ros_pose_topic_moves_the_node_in_the_running_emulator():
    import rclpy
    from nav_msgs.msg import Odometry

    from uwgen.emulator import run_emulator
    from uwgen.emulator.ros_pose import PoseFeeds

    base = fast_link()
    feed = PoseFeed("/test_vehicle/odom", "nav_msgs/msg/Odometry", scale=100.0,
                    offset=(0.0, 0.0, 50.0))
    scen = Scenario(nodes=[base.nodes[0], NodeSpec("b", dest="a", pose_topic=feed)],
                    period=base.period, bitrate=base.bitrate)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    pub_node = rclpy.create_node("test_pose_publisher", context=ctx)
    pub = pub_node.create_publisher(Odometry, "/test_vehicle/odom", 10)
    try:
        with run_emulator(scen) as emu, PoseFeeds(emu, scen) as feeds:
            msg = Odometry()
            msg.pose.pose.position.x = 12.0
            msg.pose.pose.position.y = 5.0

            def moved() -> bool:
                pub.publish(msg)
                return emu.position("b") == (1200.0, 500.0, 50.0)

            assert wait_for(moved, timeout=10.0, step=0.1)
            assert feeds.received["b"] >= 1
    finally:
        pub_node.destroy_node()
        ctx.try_shutdown()


def test_the_sample_moving_scenario_goes_out_and_comes_back():
    from .helpers import SCENARIOS
    scen = load_scenario(SCENARIOS / "moving.yaml")
    assert scen.distance("surface", "vehicle", 0.0) == pytest.approx(300.0 * (1 + (50 / 300) ** 2) ** 0.5)
    assert scen.position_at("vehicle", 750.0) == (3000.0, 0.0, 50.0)
    assert scen.position_at("vehicle", 2000.0) == (300.0, 0.0, 50.0)
    with_manifest = load_scenario(SCENARIOS / "moving.yaml",
                                  base_nodes=[NodeSpec("surface", port=4000, period=0.2,
                                                       max_read_length=64),
                                              NodeSpec("vehicle", port=4001, period=0.2,
                                                       max_read_length=64)])
    assert with_manifest.moves("vehicle")


def test_a_pose_type_that_cannot_be_loaded_is_a_clear_error():
    from uwgen.emulator.ros_pose import PoseFeedError, load_type
    with pytest.raises(PoseFeedError, match="no_such_pkg/msg/Odometry is not available"):
        load_type("no_such_pkg/msg/Odometry")
    with pytest.raises(PoseFeedError, match="nav_msgs/msg/NoSuchType"):
        load_type("nav_msgs/msg/NoSuchType")
    assert load_type("nav_msgs/msg/Odometry").__name__ == "Odometry"


def test_emulate_with_an_unloadable_pose_type_exits_1_with_the_reason(tmp_path, capsys):
    from uwgen.cli import main
    path = tmp_path / "s.yaml"
    path.write_text("nodes:\n  - {name: a, port: 0}\n  - {name: b, port: 0, pose_topic: "
                    "{topic: /b/odom, type: no_such_pkg/msg/Odometry}}\n")
    assert main(["emulate", str(path), "--duration", "0.1"]) == 1
    assert "not available to rclpy" in capsys.readouterr().err
