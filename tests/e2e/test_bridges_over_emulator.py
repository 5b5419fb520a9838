"""Both bridges, real rclpy graphs and the real link, over the DESERT emulator."""
from __future__ import annotations

import statistics
import time

from geometry_msgs.msg import Twist
from std_msgs.msg import String
from std_srvs.srv import SetBool

from uwgen.runtime.link.scheduler import DROP_REASONS

from bridge.fakes import wait_for

from .conftest import network


def subscribe(node, cls, topic, stamp=False):
    got = []
    node.create_subscription(cls, topic, (lambda m: got.append((time.monotonic(), m))) if stamp
                             else got.append, 10)
    return got


def log_ends(net):
    """The vehicle's /log publisher and what the surface hears of it, once the bridges are up:
    (heard, publisher)."""
    logs = subscribe(net.surface.node("op"), String, "/log")
    pub = net.vehicle.node("sim").create_publisher(String, "/log", 10)
    wait_for(lambda: net.connected() and pub.get_subscription_count(), what="bridges up")
    return logs, pub


def test_topics_cross_in_both_directions(net):
    cmds = subscribe(net.vehicle.node("sim"), Twist, "/cmd_vel")
    logs = subscribe(net.surface.node("op"), String, "/log")
    cmd_pub = net.surface.node("op_pub").create_publisher(Twist, "/cmd_vel", 10)
    log_pub = net.vehicle.node("sim_pub").create_publisher(String, "/log", 10)
    wait_for(lambda: net.connected() and cmd_pub.get_subscription_count()
             and log_pub.get_subscription_count(), what="bridges up")
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.5, -0.25
    cmd_pub.publish(twist)
    log_pub.publish(String(data="vehicle ready"))
    wait_for(lambda: cmds and logs, what="both directions")
    assert (cmds[0].linear.x, cmds[0].angular.z) == (0.5, -0.25)
    assert logs[0].data == "vehicle ready"
    # Nothing received was sent back: the vehicle offered no /cmd_vel, the surface no /log.
    assert net.bridges["vehicle"].status()["topics"]["/cmd_vel"]["direction"] == "in"
    assert 4 not in net.bridges["vehicle"].link.stats()["channels"]
    assert 7 not in net.bridges["surface"].link.stats()["channels"]


def test_service_round_trip(net):
    calls = net.serve_enable()
    client = net.surface.node("caller").create_client(SetBool, "/enable")
    assert client.wait_for_service(timeout_sec=5.0)
    wait_for(lambda: net.connected()
             and net.bridges["vehicle"]._served[20][1].service_is_ready(), what="server visible")
    future = client.call_async(SetBool.Request(data=True))
    wait_for(future.done, what="the response over the link")
    assert (future.result().success, future.result().message) == (True, "enabled=True")
    assert calls == [True]
    assert net.bridges["surface"].status()["services"]["/enable"]["calls"]["completed"] == 1


def test_bridges_sharing_one_graph_do_not_loop_a_call(e2e_package):
    """Both bridges and the real server in one ROS domain (a forgotten ROS_DOMAIN_ID): one
    call runs the real server once, nothing goes round over the link."""
    with network(e2e_package, same_domain=True) as net:
        calls = net.serve_enable()
        sb, vb = net.bridges["surface"], net.bridges["vehicle"]
        wait_for(lambda: net.connected()
                 and "/enable" in sb.status()["echo_hazards"] and 20 not in sb.standins.services,
                 what="the stand-in withdrawn")
        client = net.surface.node("caller").create_client(SetBool, "/enable")
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(SetBool.Request(data=True))
        wait_for(future.done, what="the real server's response")
        time.sleep(1.0)                     # several round trips of the link: room for a loop
        assert calls == [True]
        assert vb.service_counters[20].requests == 0
        assert sb.link.stats()["channels"][20]["offered"] == 0


def test_service_timeout_when_nobody_answers(e2e_package):
    # No vehicle bridge: the request crosses the link and is dropped by DESERT (no client).
    with network(e2e_package, bridges=("surface",)) as net:
        client = net.surface.node("caller").create_client(SetBool, "/enable")
        assert client.wait_for_service(timeout_sec=5.0)
        wait_for(lambda: net.connected("surface"), what="surface link up")
        sent_at = time.monotonic()
        future = client.call_async(SetBool.Request(data=True))
        bridge = net.bridges["surface"]
        wait_for(lambda: bridge.service_counters[20].timeouts == 1, timeout=5.0, what="timeout")
        assert time.monotonic() - sent_at >= 1.5          # the manifest's timeout, not earlier
        assert not future.done()                         # documented: no response is sent
        assert bridge.status()["services"]["/enable"]["calls"]["outstanding"] == 0
        client.remove_pending_request(future)


def test_long_message_is_fragmented_and_reassembled(net):
    logs, pub = log_ends(net)
    text = "".join(f"line {i:03d}: all systems nominal; " for i in range(20))  # ~640 bytes
    assert len(text.encode()) > 255
    pub.publish(String(data=text))
    wait_for(lambda: logs, timeout=15.0, what="the long message")
    assert logs[0].data == text
    chan = net.bridges["vehicle"].link.stats()["channels"][7]
    assert chan["fragments_sent"] >= 3


def test_link_outage_and_recovery(net):
    logs, pub = log_ends(net)
    pub.publish(String(data="before"))
    wait_for(lambda: len(logs) == 1, what="first message")
    net.emu.restart()           # DESERT dies and comes back: clients are disconnected
    wait_for(lambda: all(net.bridges[s].link.stats()["connection"]["reconnects"] >= 1
                         for s in ("surface", "vehicle")) and net.connected(),
             timeout=15.0, what="both links reconnected")
    pub.publish(String(data="after"))
    wait_for(lambda: len(logs) == 2, timeout=10.0, what="message after the outage")
    assert [m.data for m in logs] == ["before", "after"]


def test_latency_stays_bounded_under_overload(e2e_package):
    """10 Hz cmd_vel over one 64-byte packet per 0.2 s: the latest-queue and rate policy keep
    latency under about two periods plus propagation, and drops account for the rest."""
    period, distance = 0.2, 300.0
    with network(e2e_package, period=period, distance=distance, bitrate=4800.0) as net:
        got = subscribe(net.vehicle.node("sim"), Twist, "/cmd_vel", stamp=True)
        pub = net.surface.node("op").create_publisher(Twist, "/cmd_vel", 10)
        wait_for(lambda: net.connected() and pub.get_subscription_count(),
                 what="bridges up")
        sent_at = {}
        n = 60                                        # 6 s at 10 Hz
        start = time.monotonic()
        for k in range(1, n + 1):
            while time.monotonic() < start + k * 0.1:
                time.sleep(0.005)
            msg = Twist()
            msg.linear.x, msg.linear.z = 0.3, float(k)
            sent_at[k] = time.monotonic()
            pub.publish(msg)
        bridge = net.bridges["surface"]
        wait_for(lambda: bridge.topic_counters[4].taken == n, what="all taken")
        wait_for(lambda: bridge.link.stats()["channels"][4]["queued"] == 0, timeout=5.0,
                 what="queue drained")
        chan = bridge.link.stats()["channels"][4]
        wait_for(lambda: len(got) >= chan["sent"] - 2, timeout=5.0, what="deliveries")
        latencies = [t - sent_at[int(m.linear.z)] for t, m in got]
        airtime = (64 + 4) * 8 / 4800.0
        bound = 2 * period + distance / 1500.0 + airtime + 0.1  # + scheduling slack
        print(f"overload: {len(got)} of {n} delivered, latency median {statistics.median(latencies):.3f} s, "
              f"max {max(latencies):.3f} s, bound {bound:.3f} s, link {chan}")
        assert latencies and max(latencies) < bound, (max(latencies), bound)
        # No growth: the last messages wait no longer than the first ones.
        third = max(1, len(latencies) // 3)
        assert statistics.mean(latencies[-third:]) < statistics.mean(latencies[:third]) + 0.1
        # Every message not sent is accounted for by a policy counter: a message the poller
        # took together with a newer one (uwgen/bridge/polling.py) is superseded before the
        # link sees it, the link's latest queue supersedes the rest.
        chan = bridge.link.stats()["channels"][4]
        polled_over = bridge.topic_counters[4].superseded
        assert chan["offered"] + polled_over == n
        assert chan["sent"] + sum(chan[r] for r in DROP_REASONS) + chan["queued"] + polled_over == n
        assert chan["superseded"] + polled_over > 0
        # The rate policy (5/s) bounds what went on the link.
        assert chan["sent"] <= 5 * (time.monotonic() - start) + 1
