"""A bridge's discovery: the beacons it announces for a manifest, and what it does when."""
from __future__ import annotations

from dataclasses import replace

import pytest

from uwgen.interop.beacons import (
    Beacon, Entity, decode_beacon, encode_beacon, is_discovery_request)
from uwgen.interop.discovery import (
    DiscoveryAgent, bridge_beacons, default_node_name, discovery_policies)
from uwgen.runtime.clock import ManualClock


def kinds(beacons):
    return [(b.entity, b.topic, b.type_name) for b in beacons]


def test_surface_bridge_announces_what_it_stands_in_for(rmw_manifest):
    assert kinds(bridge_beacons(rmw_manifest, "surface")) == [
        (Entity.PUBLISHER, "/turtle1/cmd_vel", "geometry_msgs__msg/Twist"),
        (Entity.SUBSCRIBER, "/turtle1/pose", "turtlesim__msg/Pose"),
        (Entity.CLIENT, "/turtle1/teleport_absolute", "turtlesim__srv/TeleportAbsolute_Request"),
    ]


def test_vehicle_bridge_announces_the_mirror_image(rmw_manifest):
    assert kinds(bridge_beacons(rmw_manifest, "vehicle")) == [
        (Entity.SUBSCRIBER, "/turtle1/cmd_vel", "geometry_msgs__msg/Twist"),
        (Entity.PUBLISHER, "/turtle1/pose", "turtlesim__msg/Pose"),
        (Entity.SERVICE, "/turtle1/teleport_absolute", "turtlesim__srv/TeleportAbsolute_Response"),
    ]


def test_beacons_are_stable_and_named_after_the_side(rmw_manifest):
    first = bridge_beacons(rmw_manifest, "surface")
    assert first == bridge_beacons(rmw_manifest, "surface")
    assert {b.node_name for b in first} == {"surface"} == {default_node_name("surface")}
    assert default_node_name("2nd-side") == "uw_2nd_side"      # always a valid ROS node name
    assert len({b.gid for b in first}) == 3


def test_native_entries_are_not_announced(rmw_manifest):
    native = replace(rmw_manifest, topics=[replace(t, profile="native") for t in rmw_manifest.topics],
                     services=[])
    assert bridge_beacons(native, "surface") == []


def test_unknown_side_is_refused(rmw_manifest):
    with pytest.raises(KeyError, match="sides: surface, vehicle"):
        bridge_beacons(rmw_manifest, "diver")


def test_beacons_parse_in_the_independent_peer(rmw_manifest, peer):
    for beacon in bridge_beacons(rmw_manifest, "vehicle"):
        fields = peer.parse_beacon(peer.read_items(encode_beacon(beacon)))
        assert (fields["node"], fields["topic"], fields["type"], fields["gid"]) == (
            beacon.node_name, beacon.topic, beacon.type_name, beacon.gid.hex())
        assert fields["entity"] == beacon.entity.name.lower()


class Recorder:
    def __init__(self, accept=True):
        self.sent: list[tuple[int, bytes]] = []
        self.accept = accept

    def __call__(self, key, payload):
        self.sent.append((key, payload))
        return self.accept


def make_agent(rmw_manifest, accept=True):
    send = Recorder(accept)
    agent = DiscoveryAgent(bridge_beacons(rmw_manifest, "vehicle"), send, clock=ManualClock())
    return agent, send


def test_start_sends_one_request_then_every_beacon(rmw_manifest):
    agent, send = make_agent(rmw_manifest)
    agent.start()
    assert send.sent[0] == (2, b"\x00\x02")
    assert [k for k, _ in send.sent[1:]] == [1, 1, 1]
    assert [decode_beacon(p) for _, p in send.sent[1:]] == agent.beacons


def test_every_discovery_request_is_answered_with_all_beacons(rmw_manifest):
    agent, send = make_agent(rmw_manifest)
    for _ in range(2):
        assert agent.handle(b"\x00\x02") is True
    assert len(send.sent) == 6 and all(k == 1 for k, _ in send.sent)
    assert not any(is_discovery_request(p) for _, p in send.sent)
    assert agent.stats()["requests_heard"] == 2


def test_heard_beacons_go_to_the_graph_and_own_ones_do_not(rmw_manifest):
    agent, _ = make_agent(rmw_manifest)
    remote = Beacon("teleop", "/", Entity.CLIENT, bytes(16), "/turtle1/teleport_absolute",
                    "turtlesim__srv/TeleportAbsolute_Request")
    assert agent.handle(encode_beacon(remote)) is True
    assert agent.handle(encode_beacon(agent.beacons[0])) is True  # an echo of our own
    assert [e.node_name for e in agent.graph.entities()] == ["teleop"]


def test_stop_withdraws_every_entity_and_ignores_later_requests(rmw_manifest):
    agent, send = make_agent(rmw_manifest)
    agent.stop()
    gone = [decode_beacon(p) for _, p in send.sent]
    assert [b.gid for b in gone] == [b.gid for b in agent.beacons]
    assert all(b.disconnect and b.topic == "" and b.type_name == "" for b in gone)
    agent.handle(b"\x00\x02")
    agent.stop()
    assert len(send.sent) == 3


def test_malformed_discovery_is_counted_and_other_payloads_are_not_taken(rmw_manifest):
    agent, send = make_agent(rmw_manifest)
    assert agent.handle(b"\x00\x01\x61") is True
    assert agent.handle(b"\x00\x02\x00") is True
    assert agent.handle(b"\x00\x04\xf9\x00\x00") is False
    assert agent.stats()["malformed"] == 2 and send.sent == []


def test_refused_offers_are_counted(rmw_manifest):
    agent, _ = make_agent(rmw_manifest, accept=False)
    agent.start()
    stats = agent.stats()
    assert stats["refused"] == 4 and stats["beacons_sent"] == 0


def test_policies_queue_two_rounds_of_beacons():
    policies = discovery_policies(5)
    assert policies[1].queue == "fifo" and policies[1].depth == 10
    assert policies[2].queue == "latest"


def test_a_request_heard_while_a_whole_round_waits_in_the_link_adds_no_round(rmw_manifest):
    send = Recorder()
    waiting = {"n": 0}
    agent = DiscoveryAgent(bridge_beacons(rmw_manifest, "vehicle"), send, clock=ManualClock(),
                           queued=lambda: waiting["n"])
    agent.start()
    waiting["n"] = 3                      # the start-up round has not left yet (link not up)
    agent.handle(b"\x00\x02")
    agent.announce(request=True)          # a reconnect: the request goes, the round is not doubled
    assert [k for k, _ in send.sent] == [2, 1, 1, 1, 2]
    assert agent.stats()["rounds_skipped"] == 2


def test_a_request_heard_after_part_of_the_round_left_gets_a_full_round(rmw_manifest):
    send = Recorder()
    agent = DiscoveryAgent(bridge_beacons(rmw_manifest, "vehicle"), send, clock=ManualClock(),
                           queued=lambda: 2)  # one beacon of the round already went out
    agent.handle(b"\x00\x02")
    assert [k for k, _ in send.sent] == [1, 1, 1]


def test_derived_gids_cost_one_cbor_byte_per_gid_byte(rmw_manifest):
    for beacon in bridge_beacons(rmw_manifest, "vehicle"):
        assert all(b < 24 for b in beacon.gid)
        payload = encode_beacon(beacon)
        gid_items = bytes([0x10]) + beacon.gid           # count 16, then 16 one-byte integers
        assert gid_items in payload
