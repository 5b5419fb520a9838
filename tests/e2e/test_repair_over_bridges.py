"""A topic with `repair: 2` in the manifest, from the manifest to the wire and back, over a lossy link."""
from __future__ import annotations

import random
import time

import pytest
from std_msgs.msg import String

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator import NodeSpec, Scenario, run_emulator
from uwgen.runtime.link.link import Link

from bridge.fakes import wait_for
from bridge.harness import ros_sides

from .conftest import build_package

MANIFEST = """\
network: fec
package: uwgen_fec
fragment_id: 250
sides:
  surface: {port: 4000, link: {max_read_length: 64, period: 0.05}}
  vehicle: {port: 4001, link: {max_read_length: 64, period: 0.05}}
topics:
  - name: /report
    id: 9
    type: std_msgs/msg/String
    publisher: vehicle
    queue: fifo
    depth: 50
    repair: 2
"""


@pytest.fixture(scope="module")
def fec_package(tmp_path_factory):
    return build_package(tmp_path_factory.mktemp("fec"), MANIFEST, "uwgen_fec")


def test_repair_fragments_rebuild_reports_over_a_lossy_link(fec_package):
    assert fec_package.TOPICS[9].policy.repair == 2
    scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", port=0, position=(30.0, 0.0, 0.0), dest="surface")],
                    period=0.05, max_read_length=64, bitrate=48000.0, per=0.2, seed=3)
    with run_emulator(scen) as emu, ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = {}
        for side, ros in (("surface", surface), ("vehicle", vehicle)):
            plan = BridgePlan.from_package(fec_package, side)
            node = BridgeNode(plan, plan.options(port=emu.port(side), status_period=0),
                              context=ros.context, rng=random.Random(5),
                              link_factory=lambda **kw: Link(fragment_timeout=1.0, **kw))
            bridges[side] = ros.add(node)
        got = []
        surface.node("op").create_subscription(String, "/report", got.append, 50)
        pub = vehicle.node("sim").create_publisher(String, "/report", 50)
        wait_for(lambda: all(b.link.stats()["connected"] for b in bridges.values())
                 and pub.get_subscription_count(), what="bridges up")
        texts = [f"report {i:02d}: " + "depth ok, battery ok, thruster ok; " * 4 for i in range(30)]
        for text in texts:                     # 155-byte payloads: 4 data + 2 repair fragments each
            pub.publish(String(data=text))
            time.sleep(0.02)
        vb, sb = bridges["vehicle"], bridges["surface"]
        wait_for(lambda: vb.link.stats()["channels"][9]["queued"] == 0, timeout=30.0, what="sent")
        time.sleep(1.5)
        chan = vb.link.stats()["channels"][9]
        frag = sb.link.stats()["fragments"]
    print(f"repair over bridges: {len(got)} of 30 delivered, fragments {frag}")
    assert chan["sent"] == 30 and chan["fragments_sent"] == 30 * 6
    delivered = [m.data for m in got]
    assert delivered == [t for t in texts if t in set(delivered)]          # in order, intact
    # 20 % loss: without repair about 0.8^4 = 41 % would arrive; with two repairs about 90 %.
    assert len(delivered) >= 24 and frag["rebuilt"] >= 1
