"""Counters of a lossy end-to-end run add up exactly (docs/link-robustness.md).

Both bridges over the emulator at 20 % packet loss. On the publishing side:
published = taken + dropped by the subscription, taken = sent + dropped by policy + queued;
on the receiving side: received = delivered + dropped on receive; across: sent = received +
lost, where the emulator's record of delivered packets shows independently which frames
arrived (packet-aligned writes: the frames in the packets that arrived are exactly what a
receiver can get).
"""
from __future__ import annotations

import random
import time
from contextlib import contextmanager

from geometry_msgs.msg import Twist
from std_msgs.msg import String

from uwgen.runtime.delivery import ledger
from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import ShortFrameDecoder
from uwgen.runtime.link.link import Link

from bridge.fakes import wait_for
from bridge.harness import ros_sides

PERIOD = 0.05


@contextmanager
def lossy_network(package, per: float):
    scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", port=0, position=(30.0, 0.0, 0.0), dest="surface")],
                    period=PERIOD, max_read_length=64, bitrate=48000.0, per=per, seed=11)
    with run_emulator(scen, record=True) as emu, ros_sides("surface", "vehicle") as sides:
        bridges = {}
        for side, ros in zip(("surface", "vehicle"), sides):
            plan = BridgePlan.from_package(package, side)
            options = plan.options(port=emu.port(side), period=PERIOD, status_period=0)
            node = BridgeNode(plan, options, context=ros.context, rng=random.Random(7),
                              link_factory=lambda **kw: Link(fragment_timeout=1.0, **kw))
            bridges[side] = ros.add(node)
        yield emu, sides, bridges


def frames_with_header(deliveries, node: str, header: bytes) -> int:
    """Messages (wire format 2: inside each packet's envelope) whose payload starts with header."""
    stream = b"".join(d.data for d in deliveries if d.node == node)
    return sum(1 for f in ShortFrameDecoder().feed(stream) for m in envelope.decode(f).messages
               if envelope.to_v1(m).startswith(header))


def test_counters_of_a_lossy_run_add_up_exactly(e2e_package):
    with lossy_network(e2e_package, per=0.2) as (emu, (surface, vehicle), bridges):
        cmd_pub = surface.node("op").create_publisher(Twist, "/cmd_vel", 10)
        log_pub = vehicle.node("sim").create_publisher(String, "/log", 10)
        # up: connected, and each has measured the other's clock (before that a cmd_vel of
        # ttl 2 s is refused stale at the link: docs/seams.md section 8)
        wait_for(lambda: all(b.link.stats()["connected"] and b.reliability.offsets.peers()
                             for b in bridges.values())
                 and cmd_pub.get_subscription_count() and log_pub.get_subscription_count(),
                 what="bridges up")
        published_cmd, published_log = 80, 40
        for i in range(max(published_cmd, published_log)):
            if i < published_cmd:
                msg = Twist()
                msg.linear.x = float(i)
                cmd_pub.publish(msg)          # 40 Hz against `latest`, rate 5: most superseded
            if i < published_log:              # every 4th line is long: fragmented
                text = f"line {i}: " + ("all systems nominal; " * 16 if i % 4 == 0 else "ok")
                log_pub.publish(String(data=text))
            time.sleep(0.025)
        sb, vb = bridges["surface"], bridges["vehicle"]
        wait_for(lambda: sb.topic_counters[4].taken == published_cmd
                 and vb.topic_counters[7].taken == published_log, what="all taken")
        wait_for(lambda: sb.link.stats()["channels"][4]["queued"] == 0
                 and vb.link.stats()["channels"][7]["queued"] == 0, timeout=30.0, what="queues drained")
        time.sleep(1.0 + 8 * PERIOD)          # the last packets land; partial messages time out
        wait_for(lambda: sb.link.stats()["fragments"]["pending"] == 0, what="partials settled")
        status = {side: b.status() for side, b in bridges.items()}
        deliveries = emu.deliveries()
        lost_packets = emu.counters("vehicle")["lost_per"] + emu.counters("surface")["lost_per"]

    cmd_out = status["surface"]["topics"]["/cmd_vel"]["accounting"]
    cmd_in = status["vehicle"]["topics"]["/cmd_vel"]["accounting"]
    log_out = status["vehicle"]["topics"]["/log"]["accounting"]
    log_in = status["surface"]["topics"]["/log"]["accounting"]
    print(f"cmd {cmd_out} -> {cmd_in}\nlog {log_out} -> {log_in}")
    for acc in (cmd_out, cmd_in, log_out, log_in):
        assert ledger.imbalances(acc) == [], acc
    # What the test published is what the bridges account for.
    assert cmd_out["published"] == published_cmd and log_out["published"] == published_log
    assert cmd_out["dropped_by_subscription"] == log_out["dropped_by_subscription"] == 0
    assert cmd_out["dropped_by_policy"]["superseded"] > 0 and cmd_out["queued"] == log_out["queued"] == 0
    # sent = received + lost, with what arrived checked against the emulator's delivered packets.
    assert lost_packets > 0
    cmd = ledger.across(cmd_out, cmd_in)
    assert cmd["received"] == frames_with_header(deliveries, "vehicle", b"\x00\x04")
    assert cmd["sent"] == cmd["received"] + cmd["lost"] and cmd["lost"] >= 0
    log = ledger.across(log_out, log_in)
    assert log["sent"] == log["received"] + log["lost"] and log["lost"] > 0
    assert 0 <= log["lost_on_link"] <= log["lost"]
    # Unfragmented lines that arrived are all received; the rest of what was received were rebuilt.
    short_logs = frames_with_header(deliveries, "surface", b"\x00\x07")
    assert log["received"] >= short_logs
    assert log_in["delivered"] == log["received"]
