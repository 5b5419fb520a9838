"""Two rmw_desert-like peers find each other and talk through the DESERT emulator.

This is the set-up the bridge <-> rmw_desert end-to-end test uses, with a peer in the
bridge's place: discovery (request, beacons, wait_for_service), a topic and a service
call, all across emulated acoustic packets that cut frames at arbitrary points.
"""
from __future__ import annotations

import json

from conftest import peer_events, start_peer
from uwgen.emulator import NodeSpec, Scenario, TdmaSpec, run_emulator

TABLE = {"/discovery": 1, "/discovery_request": 2, "/chatter": 4, "/set_bool": 13}


def test_client_finds_service_and_subscriber_gets_messages_over_the_emulator(tmp_path):
    conf = tmp_path / "ros_allowed_topics.conf"
    conf.write_text(json.dumps({"topics": TABLE}))
    # TDMA (guard > propagation + packet time) keeps the start-up bursts from colliding;
    # small packets cut every frame.
    scenario = Scenario(nodes=[NodeSpec("vehicle", position=(0, 0, 0), dest="surface"),
                               NodeSpec("surface", position=(15, 0, 0), dest="vehicle")],
                        period=0.02, max_read_length=32, bitrate=48000, per=0.0, seed=3,
                        tdma=TdmaSpec(frame=0.2, guard=0.03))
    with run_emulator(scenario) as emu:
        vehicle = start_peer(emu.port("vehicle"), conf, "--node", "turtlesim",
                             "--pub", "/chatter=std_msgs/msg/String", "--count", "3",
                             "--rate", "10", "--data", '/chatter={"data": "hello"}',
                             "--pub-when-subscribed", "--serve", "/set_bool=std_srvs/srv/SetBool",
                             "--data", '/set_bool={"success": true, "message": "ok"}',
                             "--expect", "/set_bool=1", "--until-done", "--duration", "20")
        line = vehicle.stdout.readline()        # connected: now the surface may start
        assert json.loads(line)["event"] == "connected"
        surface = start_peer(emu.port("surface"), conf, "--node", "teleop",
                             "--sub", "/chatter=std_msgs/msg/String", "--expect", "/chatter=3",
                             "--call", "/set_bool=std_srvs/srv/SetBool",
                             "--data", '/set_bool={"data": true}', "--wait-for-service",
                             "--until-done", "--duration", "20")
        got = peer_events(surface)
        served = peer_events(vehicle)
    assert surface.returncode == 0 and vehicle.returncode == 0

    summary = got[-1]
    assert summary["ok"] and summary["received"] == {"/chatter": 3}
    assert [e["data"] for e in got if e["event"] == "message"] == [{"data": "hello"}] * 3
    beacons = {(e["node"], e["entity"], e["topic"], e["type"]) for e in got if e["event"] == "beacon"}
    assert ("turtlesim", "service", "/set_bool", "std_srvs__srv/SetBool_Response") in beacons
    assert ("turtlesim", "publisher", "/chatter", "std_msgs__msg/String") in beacons
    called = next(e for e in got if e["event"] == "called")
    response = next(e for e in got if e["event"] == "response")
    assert response["seq"] == called["seq"]
    assert response["data"] == {"success": True, "message": "ok"}
    # The call went out only after the service's beacon arrived (wait_for_service).
    first_service_beacon = next(e["t"] for e in got if e["event"] == "beacon"
                                and e["entity"] == "service")
    assert called["t"] >= first_service_beacon

    request = next(e for e in served if e["event"] == "request")
    assert request["seq"] == called["seq"] and request["data"] == {"data": True}
    assert any(e["event"] == "discovery_request" for e in served)
