"""End to end: a uwgen bridge in profile rmw_desert and an rmw_desert node share DESERT.

The surface runs ROS nodes and the uwgen bridge of side `surface` (in this process, on
rclpy); the vehicle is the independent rmw_desert peer (tests/peers/rmw_desert_peer.py)
on the emulator's vehicle port. Messages and services cross in rmw_desert's format in
both directions, and discovery works both ways: rmw_desert's wait_for_service finds a
service the bridge stands in for, the bridge's ~/status lists what the peer announced,
and the bridge withdraws its entities when it closes and announces them again when its
link reconnects.
"""
from __future__ import annotations

import gc

import os
import threading
import time
from pathlib import Path

import pytest
from conftest import peer_events, start_peer

MANIFEST = """\
network: interop
profile: rmw_desert
schema_id: 249       # the bridge announces fingerprints; the peer ignores them and never announces
sides:
  surface: {port: 4000, link: {max_read_length: 64, period: 0.02}}
  vehicle: {port: 4001, link: {max_read_length: 64, period: 0.02}}
topics:
  - {name: /cmd, id: 4, type: geometry_msgs/msg/Twist, publisher: surface, queue: fifo, depth: 8}
  - {name: /state, id: 5, type: std_msgs/msg/String, publisher: vehicle}
services:
  - {name: /arm, id: 6, type: std_srvs/srv/SetBool, server: vehicle, timeout: 8}
  - {name: /reset, id: 7, type: std_srvs/srv/Trigger, server: surface, timeout: 8}
"""


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    from uwgen.codegen import generate
    root = tmp_path_factory.mktemp("interop")
    manifest = root / "uwgen.yaml"
    manifest.write_text(MANIFEST)
    conf = root / "ros_allowed_topics.conf"
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.interop.rmw_config import export_conf
    from uwgen.manifest.loader import load_manifest
    conf.write_text(export_conf(load_manifest(manifest, InterfaceLibrary())).text)
    pkg = generate(root / "gen", "uwgen_interop", manifest=manifest,
                   profiles=("native", "rmw_desert"))
    return pkg, conf


class Surface:
    """The surface computer: an rclpy context with the bridge and the test's ROS nodes."""

    def __init__(self, pkg, port: int):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from uwgen.bridge.node import BridgeNode
        from uwgen.bridge.plan import BridgePlan

        self.context = Context()
        rclpy.init(context=self.context, domain_id=int(os.environ["ROS_DOMAIN_ID"]),
                   signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        plan = BridgePlan.from_package(pkg, "surface")
        self.bridge = BridgeNode(plan, plan.options(port=port, status_period=0),
                                 context=self.context)
        self.node = rclpy.create_node("surface_test", context=self.context)
        # single-threaded, as `uwgen bridge` spins (a MultiThreadedExecutor spins hot while
        # its pool runs a callback: docs/operators.md, "Diagnostics")
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.bridge)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:
            pass

    def close(self):
        import rclpy
        for node in (self.node, self.bridge):
            self.executor.remove_node(node)
        self.bridge.close()
        self.node.destroy_node()
        self.executor.shutdown(timeout_sec=1.0)
        if self.context.ok():
            rclpy.shutdown(context=self.context)
        self.thread.join(timeout=2.0)
        self.context.destroy()          # its participant leaves the domain now (bridge/harness.py)
        gc.collect()


def start_app_peer(port: int, conf: Path, *args: str):
    """The peer as the vehicle's application node."""
    return start_peer(port, conf, "--node", "vehicle_app", *args)


def scenario():
    from uwgen.emulator import NodeSpec, Scenario, TdmaSpec
    return Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(15, 0, 0), dest="surface")],
                    period=0.02, max_read_length=64, bitrate=48000, per=0.0, seed=5,
                    tdma=TdmaSpec(frame=0.2, guard=0.03))


def wait_for(cond, timeout=15.0, what="condition"):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def test_messages_and_calls_cross_between_bridge_and_rmw_desert_peer(package):
    from geometry_msgs.msg import Twist
    from std_msgs.msg import String
    from std_srvs.srv import SetBool, Trigger

    from uwgen.emulator import run_emulator
    from uwgen.interop.beacons import Entity

    pkg, conf = package
    with run_emulator(scenario()) as emu:
        surface = Surface(pkg, emu.port("surface"))
        try:
            got: list[str] = []
            surface.node.create_subscription(String, "/state", lambda m: got.append(m.data), 10)
            surface.node.create_service(
                Trigger, "/reset", lambda req, resp: (setattr(resp, "success", True),
                                                      setattr(resp, "message", "reset done"),
                                                      resp)[-1])
            wait_for(lambda: surface.bridge.link.stats().get("connected"), what="bridge link")
            peer = start_app_peer(
                emu.port("vehicle"), conf,
                "--sub", "/cmd=geometry_msgs/msg/Twist", "--expect", "/cmd=2",
                "--pub", "/state=std_msgs/msg/String", "--data", '/state={"data": "docked"}',
                "--count", "3", "--rate", "5", "--pub-delay", "0.5",
                "--serve", "/arm=std_srvs/srv/SetBool",
                "--data", '/arm={"success": true, "message": "armed"}', "--expect", "/arm=1",
                "--call", "/reset=std_srvs/srv/Trigger", "--call-delay", "0.5",
                "--until-done", "--duration", "20")
            pub = surface.node.create_publisher(Twist, "/cmd", 10)
            client = surface.node.create_client(SetBool, "/arm")
            assert client.wait_for_service(timeout_sec=10)
            # The peer is connected once its beacons arrived (DESERT drops bytes for a node
            # without client, so publishing earlier could lose the commands).
            graph = surface.bridge.discovery.graph
            wait_for(lambda: graph.has(Entity.SERVICE, "/arm"), what="the peer's /arm beacon")
            for x in (1.5, -2.25):
                msg = Twist()
                msg.linear.x = x
                msg.angular.z = 1.8
                pub.publish(msg)
            future = client.call_async(SetBool.Request(data=True))
            wait_for(future.done, what="the /arm response")
            assert (future.result().success, future.result().message) == (True, "armed")
            wait_for(lambda: len(got) >= 3, what="/state messages")
            events = peer_events(peer)
            schema = surface.bridge.status()["schema"]
            # Announced to the peer, which ignores them; it never announces, so nothing is refused.
            assert schema["payloads_sent"] >= 1 and schema["heard"] == {} and schema["refused"] == 0
        finally:
            surface.close()

    assert got[:3] == ["docked"] * 3
    summary = events[-1]
    assert summary["ok"], summary
    cmds = [e["data"] for e in events if e["event"] == "message"]
    assert [(c["linear"]["x"], round(c["angular"]["z"], 5)) for c in cmds] == [(1.5, 1.8), (-2.25, 1.8)]
    request = next(e for e in events if e["event"] == "request")
    assert request["data"] == {"data": True}
    assert 1 <= request["seq"] <= 999      # the bridge as a client of an rmw_desert server
    response = next(e for e in events if e["event"] == "response")
    assert response["data"] == {"success": True, "message": "reset done"}


def test_rmw_desert_wait_for_service_finds_the_bridge(package):
    from std_srvs.srv import Trigger

    from uwgen.emulator import run_emulator

    pkg, conf = package
    with run_emulator(scenario()) as emu:
        surface = Surface(pkg, emu.port("surface"))
        try:
            surface.node.create_service(
                Trigger, "/reset", lambda req, resp: (setattr(resp, "success", True), resp)[-1])
            wait_for(lambda: surface.bridge.link.stats().get("connected"), what="bridge link")
            # seq 0: rmw_desert clients pick 0..999, and the bridge must echo even 0.
            peer = start_app_peer(emu.port("vehicle"), conf, "--call", "/reset=std_srvs/srv/Trigger",
                              "--wait-for-service", "--sub", "/cmd=geometry_msgs/msg/Twist",
                              "--seq", "0", "--until-done", "--duration", "5")
            events = peer_events(peer)
            # The peer's beacons, then its disconnect beacons at exit, reached the bridge.
            heard = surface.bridge.discovery.stats()
            assert heard["graph"]["added"] == 2 and heard["requests_heard"] >= 1
            wait_for(lambda: surface.bridge.status()["discovery"]["remote"] == [],
                     what="the peer's entities withdrawn")
            assert surface.bridge.discovery.stats()["graph"]["removed"] == 2
        finally:
            surface.close()
    beacons = {(e["entity"], e["topic"], e["type"]) for e in events if e["event"] == "beacon"}
    assert ("service", "/reset", "std_srvs__srv/Trigger_Response") in beacons
    assert ("publisher", "/cmd", "geometry_msgs__msg/Twist") in beacons
    assert ("client", "/arm", "std_srvs__srv/SetBool_Request") in beacons
    assert ("subscriber", "/state", "std_msgs__msg/String") in beacons
    assert events[-1]["ok"] and events[-1]["calls"] == {"/reset": True}
    called = next(e for e in events if e["event"] == "called")
    response = next(e for e in events if e["event"] == "response")
    assert called["seq"] == response["seq"] == 0


def test_bridge_status_lists_the_peer_and_its_close_withdraws_the_bridge(package):
    from uwgen.emulator import run_emulator
    from uwgen.interop.discovery import default_node_name

    pkg, conf = package
    with run_emulator(scenario()) as emu:
        surface = Surface(pkg, emu.port("surface"))
        closed = False
        try:
            wait_for(lambda: surface.bridge.link.stats().get("connected"), what="bridge link")
            peer = start_app_peer(emu.port("vehicle"), conf, "--sub", "/cmd=geometry_msgs/msg/Twist",
                              "--serve", "/arm=std_srvs/srv/SetBool", "--duration", "2")
            remote = lambda: {(e["node"], e["entity"], e["topic"])  # noqa: E731
                              for e in surface.bridge.status()["discovery"]["remote"]}
            wait_for(lambda: len(remote()) == 2, what="the peer's entities in ~/status")
            assert remote() == {("/vehicle_app", "subscriber", "/cmd"),
                                ("/vehicle_app", "service", "/arm")}
            surface.close()
            closed = True
            events = peer_events(peer)
        finally:
            if not closed:
                surface.close()
    node = default_node_name("surface")
    announced = {e["gid"]: e for e in events
                 if e["event"] == "beacon" and not e["disconnect"] and e["node"] == node}
    withdrawn = {e["gid"] for e in events
                 if e["event"] == "beacon" and e["disconnect"] and e["node"] == node}
    assert len(announced) == 4 and withdrawn == set(announced)


def test_bridge_asks_again_and_announces_again_after_its_link_reconnects(package):
    from uwgen.emulator import run_emulator

    pkg, _ = package
    with run_emulator(scenario()) as emu:
        surface = Surface(pkg, emu.port("surface"))
        try:
            chans = lambda: surface.bridge.link.stats()["channels"]  # noqa: E731
            wait_for(lambda: chans()[2]["sent"] >= 1 and chans()[1]["sent"] >= 4,
                     what="start-up request and beacons sent")
            emu.restart()
            wait_for(lambda: surface.bridge.link.stats()["connection"]["reconnects"] >= 1,
                     what="the reconnect")
            wait_for(lambda: chans()[2]["sent"] >= 2 and chans()[1]["sent"] >= 8,
                     what="request and beacons sent again")
        finally:
            surface.close()
