"""A fleet manifest with real bridges: a surface and three vehicles on one emulated channel
under the manifest's UW/TDMA. A command reaches only the vehicle it is addressed to,
telemetry comes from each vehicle under its namespace, and a call to auv2's service is
answered by auv2 alone; the other vehicles count what they overheard, never an unknown id."""
from __future__ import annotations

import random
import time
from dataclasses import replace

import pytest
from std_msgs.msg import String
from std_srvs.srv import SetBool

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator import BROADCAST, NodeSpec, Scenario, run_emulator
from uwgen.emulator.from_manifest import with_mac

from bridge.fakes import wait_for
from bridge.harness import ros_sides

from .conftest import build_package

VEHICLES = ["auv1", "auv2", "auv3"]
PERIOD = 0.05
MANIFEST = f"""\
network: fleete2e
package: uwgen_fleete2e
mac: {{mode: tdma, frame: 0.6, guard: 0.05, max_packet_per_slot: 2, bitrate: 48000, range: 30}}
sides:
  surface: {{port: 4000, link: {{max_read_length: 64, period: {PERIOD}}}}}
fleet:
  vehicles: 3
  name: auv{{n}}
  port: 4001
  link: {{max_read_length: 64, period: {PERIOD}}}
  topics:
    - {{name: cmd, id: 10, type: std_msgs/msg/String, publisher: surface, queue: fifo, depth: 4}}
    - {{name: report, id: 11, type: std_msgs/msg/String, publisher: fleet, queue: fifo, depth: 4}}
  services:
    - {{name: enable, id: 12, type: std_srvs/srv/SetBool, server: fleet, timeout: 8}}
"""


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    return build_package(tmp_path_factory.mktemp("fleete2e"), MANIFEST, "uwgen_fleete2e")


def test_commands_reach_their_own_vehicle_and_every_vehicle_reports(fleet):
    package = fleet
    nodes = [NodeSpec("surface", dest=BROADCAST)] + [
        NodeSpec(v, position=(10.0 * (k + 1), 0.0, 0.0), dest="surface") for k, v in enumerate(VEHICLES)]
    scen = with_mac(Scenario(nodes=nodes, period=PERIOD, max_read_length=64, seed=4), package.MANIFEST.mac)
    assert scen.tdma is not None and scen.tdma.slots == 4
    names = ["surface", *VEHICLES]
    with run_emulator(replace(scen, bitrate=48000.0)) as emu, ros_sides(*names) as sides:
        ros = dict(zip(names, sides))
        bridges = {}
        for side in names:
            plan = BridgePlan.from_package(package, side)
            bridges[side] = ros[side].add(BridgeNode(
                plan, plan.options(port=emu.port(side), status_period=0),
                context=ros[side].context, rng=random.Random(3)))
        got: dict[tuple[str, str], list[str]] = {}
        served: list[str] = []
        surface = ros["surface"].node("app_surface")
        pubs = {}
        for v in VEHICLES:
            node = ros[v].node(f"app_{v}")
            node.create_subscription(String, f"/{v}/cmd",
                                     lambda m, v=v: got.setdefault((v, "cmd"), []).append(m.data), 10)

            def serve(req, resp, v=v):
                served.append(v)
                resp.success, resp.message = True, v
                return resp
            node.create_service(SetBool, f"/{v}/enable", serve)
            pubs[v] = (node.create_publisher(String, f"/{v}/report", 10),
                       surface.create_publisher(String, f"/{v}/cmd", 10))
            surface.create_subscription(String, f"/{v}/report",
                                        lambda m, v=v: got.setdefault((v, "report"), []).append(m.data), 10)
        client = surface.create_client(SetBool, "/auv2/enable")
        wait_for(lambda: all(b.link.stats()["connected"] for b in bridges.values())
                 and all(p.get_subscription_count() for pair in pubs.values() for p in pair)
                 and client.service_is_ready(), timeout=20.0, what="four bridges up")
        for v in VEHICLES:
            pubs[v][1].publish(String(data=f"go {v}"))
            pubs[v][0].publish(String(data=f"{v} here"))
        future = client.call_async(SetBool.Request(data=True))
        # 20 s is a few dozen frames; a loaded 2-core machine has taken longer (the bound
        # only matters when it fails)
        wait_for(lambda: future.done() and len(got) == 2 * len(VEHICLES), timeout=45.0,
                 what="every command, every report and the call")
        time.sleep(1.5)                                        # anything misrouted shows up
        counters = {side: bridges[side].counters for side in names}
    assert {v: got[v, "cmd"] for v in VEHICLES} == {v: [f"go {v}"] for v in VEHICLES}
    assert {v: got[v, "report"] for v in VEHICLES} == {v: [f"{v} here"] for v in VEHICLES}
    assert future.result().message == "auv2" and served == ["auv2"]
    # every vehicle heard the surface's packets for the others: overheard, never unknown
    assert all(counters[v].unknown_id == 0 for v in names)
    assert sum(counters[v].overheard for v in VEHICLES) > 0
    assert sum(c["lost_collision"] for c in emu.all_counters().values()) == 0
