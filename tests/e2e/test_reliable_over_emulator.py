"""Reliable delivery (wire-format.md section 15) over both bridges, real rclpy graphs and the emulator (wire format 2): a reliable
topic arrives complete and once through a lossy link, each side's ledger says exactly what the
other never received, a command older than its max age is refused and counted, a copy of a
request runs the server once."""
from __future__ import annotations

import time

from std_msgs.msg import String

from bridge.fakes import wait_for

from .conftest import build_package, network

MANIFEST = """\
network: e2erel
package: uwgen_e2erel
sides:
  surface: {port: 4000, link: {max_read_length: 64, period: 0.05}}
  vehicle: {port: 4001, link: {max_read_length: 64, period: 0.05}}
topics:
  - {name: /mission, id: 8, type: std_msgs/msg/String, publisher: surface, queue: fifo,
     depth: 30, ttl: 60, reliability: reliable}
  - {name: /chatter, id: 5, type: std_msgs/msg/String, publisher: vehicle, queue: fifo,
     depth: 30, ttl: 60}
services:
  - {name: /enable, id: 20, type: std_srvs/srv/SetBool, server: vehicle, timeout: 1.5}
"""
N = 20


def package(tmp_path_factory):
    return build_package(tmp_path_factory.mktemp("e2erel"), MANIFEST, "uwgen_e2erel")


def on_link(bridge, entry: str, section: str = "topics") -> dict:
    return bridge.status()[section][entry]["link"].get("on_link", {})


def test_a_reliable_topic_arrives_once_and_each_ledger_names_what_never_arrived(tmp_path_factory):
    pkg = package(tmp_path_factory)
    with network(pkg, per=0.3) as net:
        missions, chatter = [], []
        net.vehicle.node("sim").create_subscription(String, "/mission", missions.append, 50)
        net.surface.node("op").create_subscription(String, "/chatter", chatter.append, 50)
        mission_pub = net.surface.node("op_pub").create_publisher(String, "/mission", 50)
        chatter_pub = net.vehicle.node("sim_pub").create_publisher(String, "/chatter", 50)
        wait_for(lambda: net.connected() and mission_pub.get_subscription_count()
                 and chatter_pub.get_subscription_count(), what="bridges up")
        for i in range(N):
            mission_pub.publish(String(data=f"waypoint {i}"))
            chatter_pub.publish(String(data=f"chatter {i}"))
            time.sleep(0.1)
        wait_for(lambda: len(missions) >= N, timeout=60.0, what="every mission message")
        sb, vb = net.bridges["surface"], net.bridges["vehicle"]
        # the vehicle's chatter: wait until every copy it sent is named by an ack
        wait_for(lambda: on_link(vb, "/chatter").get("in_flight", 1) == 0
                 and on_link(vb, "/chatter").get("sent") == N, timeout=30.0, what="chatter acked")
        # what the link delivered reaches the ROS subscriber a little later (under load, more
        # than the 0.5 s this test once slept): wait for it, bounded, then compare exactly
        wait_for(lambda: len(chatter) >= on_link(vb, "/chatter").get("delivered", 0), timeout=10.0,
                 what="delivered chatter at the subscriber")
        time.sleep(0.3)                  # nothing more may come: a late extra would show below
        assert sorted(m.data for m in missions) == sorted(f"waypoint {i}" for i in range(N))
        mission = on_link(sb, "/mission")
        assert mission["lost_on_link"] > 0 and mission["resent"] > 0     # 30 % loss: repaired
        row = on_link(vb, "/chatter")
        assert len(chatter) < N                                            # best effort: lost
        assert (row["delivered"], row["lost_on_link"]) == (len(chatter), N - len(chatter))


def test_a_command_older_than_its_max_age_is_refused_and_a_copy_runs_once(tmp_path_factory):
    pkg = package(tmp_path_factory)
    with network(pkg) as net:
        calls = net.serve_enable()
        sb, vb = net.bridges["surface"], net.bridges["vehicle"]
        wait_for(lambda: net.connected() and vb._served[20][1].service_is_ready(),
                 what="server visible")
        link = sb.link
        # A request held back 30 s (max age: the 1.5 s timeout, plus the 5 s clock tolerance)
        link.offer(20, bytes.fromhex("02 14 07 F5"), published=link.clock.now() - 30.0)
        wait_for(lambda: vb.link.stats()["reliability"]["stale"] == 1, what="refused stale")
        assert calls == []
        assert on_link(vb, "/enable", "services").get("stale") == 1
        # A request and its copy (same seq): the server runs once, the copy is counted
        link.offer(20, bytes.fromhex("02 14 08 F4"))
        link.offer(20, bytes.fromhex("02 14 08 F4"))
        wait_for(lambda: calls and vb.service_counters[20].duplicate_requests == 1,
                 what="the request served, its copy recognised")
        time.sleep(0.5)
        assert calls == [False]


def test_a_restarted_unsealed_sender_loses_nothing_and_a_clean_stop_closes_the_peers_ledger(
        tmp_path_factory):
    """Every wire-format-2 link carries the sender's epoch (K): a surface bridge started again
    numbers its packets from 0 and is not taken for repeats; its clean stop sends the last
    acknowledgements, so the vehicle's ledger has nothing left in flight."""
    pkg = package(tmp_path_factory)
    with network(pkg) as net:
        missions, chatter = [], []
        net.vehicle.node("sim").create_subscription(String, "/mission", missions.append, 50)
        net.surface.node("op").create_subscription(String, "/chatter", chatter.append, 50)
        mission_pub = net.surface.node("op_pub").create_publisher(String, "/mission", 50)
        chatter_pub = net.vehicle.node("sim_pub").create_publisher(String, "/chatter", 50)
        wait_for(lambda: net.connected() and mission_pub.get_subscription_count()
                 and chatter_pub.get_subscription_count(), what="bridges up")
        for i in range(10):
            mission_pub.publish(String(data=f"before {i}"))
            chatter_pub.publish(String(data=f"chatter {i}"))
            time.sleep(0.05)
        wait_for(lambda: len(missions) >= 10 and len(chatter) >= 10, timeout=30.0,
                 what="both ways delivered")
        old, vb = net.bridges["surface"], net.bridges["vehicle"]
        net.surface.executor.remove_node(old)
        net.surface.nodes.remove(old)
        old.close()                                        # SIGINT/SIGTERM end here too
        wait_for(lambda: on_link(vb, "/chatter").get("in_flight", 1) == 0, timeout=5.0,
                 what="the vehicle's chatter ledger closed by the last acknowledgements")
        assert on_link(vb, "/chatter")["delivered"] == 10
        new = net.start_bridge("surface")
        wait_for(lambda: net.connected("surface") and mission_pub.get_subscription_count(),
                 what="the new surface bridge up")
        for i in range(10):
            mission_pub.publish(String(data=f"after {i}"))
            time.sleep(0.05)
        wait_for(lambda: len(missions) >= 20, timeout=30.0, what="the new start's missions")
        assert sorted(m.data for m in missions) == sorted(
            [f"before {i}" for i in range(10)] + [f"after {i}" for i in range(10)])
        assert vb.link.stats()["reliability"]["restarts_seen"] == 1
        wait_for(lambda: on_link(new, "/mission").get("delivered") == 10, timeout=10.0,
                 what="the new start's ledger: all delivered")
