"""Both bridges over the emulator under each MAC (docs/emulator.md, MACs): two-way traffic
at the link's pace loses no packet to a collision between the two sides, and DESERT's TDMA
queue stays within what a slot drains."""
from __future__ import annotations

import random
import time
from dataclasses import replace

import pytest
from geometry_msgs.msg import Twist
from std_msgs.msg import String

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.emulator.from_manifest import with_mac
from uwgen.manifest.model import MacConfig

from bridge.fakes import wait_for
from bridge.harness import ros_sides

PERIOD = 0.05
BITRATE = 48000.0
DISTANCE = 600.0          # a packet is 0.4 s on its way: carrier sense alone cannot help
MACS = {
    "turns": MacConfig(mode="turns", bitrate=BITRATE, range=DISTANCE, leader="surface",
                       packets=(("surface", 3), ("vehicle", 2))),
    # 2 slots of 1 s, guard 0.5 s (the range's 0.4 s and a packet): 2 packets a slot, far
    # fewer a frame than the period lets through.
    "tdma": MacConfig(mode="tdma", bitrate=BITRATE, range=DISTANCE, frame=2.0, guard=0.5,
                      slots=("surface", "vehicle"), max_packet_per_slot=2, queue_size=10),
}


def run_two_way(package, mac: MacConfig, seconds: float = 6.0, distance: float = DISTANCE):
    scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle", slot=0),
                           NodeSpec("vehicle", port=0, position=(distance, 0.0, 0.0), dest="surface",
                                    slot=1)],
                    period=PERIOD, max_read_length=64, bitrate=BITRATE, seed=3)
    scen = with_mac(scen, mac)
    with run_emulator(scen) as emu, ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = {}
        for side, ros in (("surface", surface), ("vehicle", vehicle)):
            plan = replace(BridgePlan.from_package(package, side), mac=mac)
            options = plan.options(port=emu.port(side), period=PERIOD, status_period=0)
            bridges[side] = ros.add(BridgeNode(plan, options, context=ros.context,
                                               rng=random.Random(7)))
        cmds, logs = [], []
        vehicle.node("sim").create_subscription(Twist, "/cmd_vel", cmds.append, 10)
        surface.node("op").create_subscription(String, "/log", logs.append, 10)
        cmd_pub = surface.node("op_pub").create_publisher(Twist, "/cmd_vel", 10)
        log_pub = vehicle.node("sim_pub").create_publisher(String, "/log", 10)
        # up, and each has measured the other's clock (docs/seams.md section 8): a command
        # with a max age under the clock tolerance is refused before that exchange
        wait_for(lambda: all(b.link.stats()["connected"] and b.reliability.offsets.peers()
                             for b in bridges.values())
                 and cmd_pub.get_subscription_count() and log_pub.get_subscription_count(),
                 timeout=30.0, what="bridges up and clocks measured")
        end = time.monotonic() + seconds
        k = 0
        while time.monotonic() < end:          # both sides offer more than the link carries
            cmd_pub.publish(Twist())
            log_pub.publish(String(data=f"line {k} " + "x" * 30))
            k += 1
            time.sleep(0.02)
        time.sleep(1.0)
        stats = {s: b.link.stats() for s, b in bridges.items()}
        return emu.all_counters(), stats, cmds, logs


@pytest.mark.parametrize("mode", sorted(MACS))
def test_two_way_traffic_loses_nothing_to_collisions(e2e_package, mode):
    counters, stats, cmds, logs = run_two_way(e2e_package, MACS[mode])
    assert cmds and logs
    for node in ("surface", "vehicle"):
        assert counters[node]["lost_collision"] == 0, counters
        assert counters[node]["packets_sent"] >= 4
    if mode == "tdma":
        for node in ("surface", "vehicle"):
            # the bridge writes what a slot drains: DESERT's MAC queue never fills
            assert counters[node]["dropped_queue_full"] == 0
            assert counters[node]["max_mac_queue"] <= 4
            assert stats[node]["mac"]["capacity_per_frame"] == 2
            # each heard the other's slot and timed its writes to its own
            assert stats[node]["mac"]["timed_writes"] > 0
    else:
        assert stats["surface"]["mac"]["ends_heard"] >= 2
        grants = stats["vehicle"]["mac"]["grants_heard"]
        assert grants >= 2
        # Nothing leaves outside a turn, acknowledgements included: the vehicle wrote at most
        # what its grants allowed (2 packets each).
        assert stats["vehicle"]["connection"]["writes"] <= 2 * grants


def test_without_a_mac_the_same_traffic_collides(e2e_package):
    """The check above can fail: mode none, the same two-way load, collides (at 600 m, where
    a packet is on its way 0.4 s, long after the other side's carrier sense has looked)."""
    counters, _stats, _cmds, _logs = run_two_way(e2e_package, MacConfig(bitrate=BITRATE), 3.0)
    assert counters["surface"]["lost_collision"] + counters["vehicle"]["lost_collision"] > 0
