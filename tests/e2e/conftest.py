"""End-to-end set-up: a generated package of installed types, the emulator, two ROS sides.

The package is generated at test time by `uwgen build` from a small manifest of installed
types (Twist, String, SetBool), so these tests do not depend on turtlesim's interfaces.
Each test gets its own emulator and two ROS domains of its own (vehicle and surface).
"""
from __future__ import annotations

import random
from contextlib import contextmanager

import pytest
from std_srvs.srv import SetBool

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan, import_package
from uwgen.emulator import NodeSpec, Scenario, run_emulator

from bridge.harness import ros_sides

MANIFEST = """\
network: e2e
package: uwgen_e2e
fragment_id: 250
sides:
  surface:
    port: 4000
    link: {max_read_length: 64, period: 0.05}
  vehicle:
    port: 4001
    link: {max_read_length: 64, period: 0.05}
topics:
  - name: /cmd_vel
    id: 4
    type: geometry_msgs/msg/Twist
    publisher: surface
    queue: latest
    rate: 5
    ttl: 2.0
    priority: 10
  - name: /log
    id: 7
    type: std_msgs/msg/String
    publisher: vehicle
    queue: fifo
    depth: 8
    ttl: 60
    priority: 0
services:
  - name: /enable
    id: 20
    type: std_srvs/srv/SetBool
    server: vehicle
    timeout: 1.5
"""


def build_package(root, manifest_text: str, package: str, keygen: bool = False):
    """`uwgen build -m` of a manifest of installed types, written to `root/uwgen.yaml`,
    into `root/generated/<package>`, imported. With `keygen`, `uwgen keygen root/net.key`
    first (the key file a secured manifest names)."""
    from uwgen.cli import main as uwgen_main

    manifest = root / "uwgen.yaml"
    manifest.write_text(manifest_text)
    if keygen:
        assert uwgen_main(["keygen", str(root / "net.key")]) == 0
    rc = uwgen_main(["build", "-m", str(manifest), "-o", str(root / "generated" / package)])
    assert rc == 0, f"uwgen build of {package} failed"
    return import_package(package, root / "generated")


@pytest.fixture(scope="session")
def e2e_package(tmp_path_factory):
    return build_package(tmp_path_factory.mktemp("e2e"), MANIFEST, "uwgen_e2e")


class Net:
    """The emulator, both ROS sides and (once started) both bridges of one test."""

    def __init__(self, package, emu, sides, period, mrl):
        self.package, self.emu = package, emu
        self.surface, self.vehicle = sides
        self.period, self.mrl = period, mrl
        self.bridges: dict[str, BridgeNode] = {}

    def start_bridge(self, side: str, **opts) -> BridgeNode:
        ros = self.surface if side == "surface" else self.vehicle
        plan = BridgePlan.from_package(self.package, side)
        options = plan.options(port=self.emu.port(side), max_read_length=self.mrl,
                               period=self.period, status_period=0, **opts)
        node = BridgeNode(plan, options, context=ros.context, rng=random.Random(7))
        self.bridges[side] = ros.add(node)
        return node

    def connected(self, *sides: str) -> bool:
        """Whether the links of the bridges of `sides` (of every bridge, none named) are up,
        and on a wire-format-2 link each has measured a peer's clock (the exchange at start,
        docs/seams.md section 8): until then a command with a max age under the 5 s clock
        tolerance cannot be promised fresh and is refused."""
        bridges = [self.bridges[s] for s in sides or self.bridges]
        alone = len(self.bridges) < 2                  # no peer to measure
        return all(b.link.stats()["connected"] and (
            alone or getattr(b, "reliability", None) is None or b.reliability.offsets.peers())
            for b in bridges)

    def serve_enable(self) -> list[bool]:
        """The real /enable server (SetBool) in the vehicle's graph: it succeeds and answers
        `enabled=<data>`. Returns the data it is called with, call by call."""
        calls: list[bool] = []

        def serve(req, resp):
            calls.append(req.data)
            resp.success, resp.message = True, f"enabled={req.data}"
            return resp
        self.vehicle.node("server").create_service(SetBool, "/enable", serve)
        return calls


@contextmanager
def network(package, *, period=0.05, mrl=64, distance=30.0, bitrate=48000.0, per=0.0,
            bridges=("surface", "vehicle"), same_domain=False):
    scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", port=0, position=(distance, 0.0, 0.0), dest="surface")],
                    period=period, max_read_length=mrl, bitrate=bitrate, per=per, seed=5)
    with run_emulator(scen) as emu, ros_sides("surface", "vehicle", same_domain=same_domain) as sides:
        net = Net(package, emu, sides, period, mrl)
        for side in bridges:
            net.start_bridge(side)
        yield net


@pytest.fixture
def net(e2e_package):
    with network(e2e_package) as n:
        yield n
