"""A fleet on one manifest: the surface and three vehicles bridged over a 16-node network.

One manifest names 16 sides (a surface station and 15 vehicles); `uwgen emulate -m`'s
mapping turns it into 16 emulated DESERT nodes (broadcast, TDMA with one slot each).
Bridges run for the surface and three vehicles, each in a ROS domain of its own: the
surface's orders reach every vehicle, and each vehicle's report reaches the surface and
the other vehicles.
"""
from __future__ import annotations

import random
import time
from dataclasses import replace

import pytest
from std_msgs.msg import String

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator import TdmaSpec, run_emulator
from uwgen.emulator.from_manifest import scenario_from_manifest

from bridge.fakes import wait_for
from bridge.harness import ros_sides

from .conftest import build_package

VEHICLES = [f"auv{i}" for i in range(1, 16)]
BRIDGED = ["surface", "auv1", "auv2", "auv3"]
PERIOD = 0.05


def fleet_manifest() -> str:
    sides = "\n".join(f"  {name}: {{port: {4000 + i}, link: {{max_read_length: 64, period: {PERIOD}}}}}"
                      for i, name in enumerate(["surface", *VEHICLES]))
    topics = ["  - {name: /fleet/order, id: 4, type: std_msgs/msg/String, publisher: surface, "
              "queue: fifo, depth: 8}"]
    topics += [f"  - {{name: /{v}/report, id: {10 + i}, type: std_msgs/msg/String, "
               f"publisher: {v}, queue: fifo, depth: 8}}" for i, v in enumerate(BRIDGED[1:])]
    return ("network: fleet\npackage: uwgen_fleet\nsides:\n" + sides + "\ntopics:\n"
            + "\n".join(topics) + "\n")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    package = build_package(root, fleet_manifest(), "uwgen_fleet")
    return root / "uwgen.yaml", package


def test_three_vehicles_and_the_surface_exchange_traffic_over_a_16_node_network(fleet):
    manifest, package = fleet
    scen = scenario_from_manifest(manifest, spacing=2.0)          # 16 nodes on a 30 m line
    assert len(scen.nodes) == 16
    # Free ports (the manifest's are for real use), a fast modem and one TDMA slot per node
    # (guard over the 20 ms of propagation across the line).
    scen = replace(scen, nodes=[replace(n, port=0) for n in scen.nodes], bitrate=48000.0,
                   tdma=TdmaSpec(frame=16 * 0.06, guard=0.045), seed=2)
    with run_emulator(scen) as emu, ros_sides(*BRIDGED) as sides:
        ros = dict(zip(BRIDGED, sides))
        bridges = {}
        for side in BRIDGED:
            plan = BridgePlan.from_package(package, side)
            options = plan.options(port=emu.port(side), max_read_length=64, period=PERIOD,
                                   status_period=0)
            bridges[side] = ros[side].add(BridgeNode(plan, options, context=ros[side].context,
                                                     rng=random.Random(7)))
        got: dict[tuple[str, str], list[str]] = {}
        pubs = {}
        for side in BRIDGED:
            node = ros[side].node(f"app_{side}")
            for topic in ["/fleet/order", *(f"/{v}/report" for v in BRIDGED[1:])]:
                if topic == ("/fleet/order" if side == "surface" else f"/{side}/report"):
                    pubs[side] = node.create_publisher(String, topic, 10)
                else:
                    box = got.setdefault((side, topic), [])
                    node.create_subscription(String, topic, lambda m, box=box: box.append(m.data), 10)
        wait_for(lambda: all(b.link.stats()["connected"] for b in bridges.values())
                 and all(p.get_subscription_count() for p in pubs.values()),
                 timeout=15.0, what="four bridges up")
        pubs["surface"].publish(String(data="survey area B"))
        for v in BRIDGED[1:]:
            pubs[v].publish(String(data=f"{v} at waypoint 3"))
        wait_for(lambda: all(got.values()), timeout=20.0, what="every side hears every other")
        time.sleep(1.5)                                            # anything duplicated shows up
    for v in BRIDGED[1:]:
        assert got[v, "/fleet/order"] == ["survey area B"]
        assert got["surface", f"/{v}/report"] == [f"{v} at waypoint 3"]
        for other in BRIDGED[1:]:
            if other != v:
                assert got[other, f"/{v}/report"] == [f"{v} at waypoint 3"]
    counters = emu.all_counters()
    assert sum(c["lost_collision"] for c in counters.values()) == 0
    # The 12 vehicles without a bridge had no client: what reached them was dropped, counted.
    assert all(counters[v]["lost_no_client"] > 0 for v in VEHICLES[3:])
