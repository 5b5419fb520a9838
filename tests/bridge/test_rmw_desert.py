"""The bridge with rmw_desert-profile entries: discovery wiring and rmw_desert service rules.

Real rclpy graphs, fake links (tests/bridge/fakes.py). The bytes on keys 1 and 2 are the
real beacon format (uwgen.interop.beacons); the peer-level checks are in tests/interop.
"""
from __future__ import annotations

import json
import logging

import pytest
from geometry_msgs.msg import Twist
from std_msgs.msg import String
from test_msgs.srv import BasicTypes

from uwgen.bridge.plan import PlanError
from uwgen.interop.beacons import (
    Beacon, Entity, decode_beacon, derive_gid, encode_beacon, encode_discovery_request,
    is_discovery_request)
from uwgen.interop.discovery import DiscoveryAgent, beacons_for, discovery_policies
from uwgen.runtime.wire.codec import load_items

from .fakes import FakeServiceCodec, FakeTopicCodec, LinkPair, fake_package, wait_for
from .harness import ros_sides, start_bridge

RMW = "rmw_desert"
CMD = FakeTopicCodec(4, "/cmd", Twist, "surface", profile=RMW)
LOG = FakeTopicCodec(7, "/log", String, "vehicle", profile=RMW)
NATIVE_LOG = FakeTopicCodec(8, "/native_log", String, "vehicle")
ECHO = FakeServiceCodec(20, "/echo", BasicTypes, "vehicle", timeout=5.0, profile=RMW)
QUICK = FakeServiceCodec(21, "/quick", BasicTypes, "vehicle", timeout=0.5, profile=RMW)
NATIVE_ECHO = FakeServiceCodec(22, "/native_echo", BasicTypes, "vehicle")


def beacons_on(link):
    return [decode_beacon(p) for p in link.offered(1)]


def remote_beacon(entity=Entity.SERVICE, topic="/reset", type_name="std_srvs__srv/Trigger_Response",
                  node="vehicle_app", gone=False):
    gid = bytes(range(16, 32)) if topic == "/reset" else bytes(range(32, 48))
    beacon = Beacon(node, "/", entity, gid, topic, type_name, False)
    return encode_beacon(beacon.gone() if gone else beacon)


@pytest.fixture
def surface_only():
    """The surface bridge alone: what it offers is recorded, nothing is delivered."""
    package = fake_package([CMD, LOG, NATIVE_LOG], [ECHO, QUICK, NATIVE_ECHO])
    links = LinkPair()
    with ros_sides("surface") as (surface,):
        bridge = start_bridge(surface, package, links.factory)
        yield surface, bridge, links.links["surface"]


# -- discovery -------------------------------------------------------------------------

def test_start_sends_one_request_then_a_beacon_per_rmw_desert_entry(surface_only):
    surface, bridge, link = surface_only
    assert [is_discovery_request(p) for p in link.offered(2)] == [True]
    assert [(b.entity, b.topic, b.type_name) for b in beacons_on(link)] == [
        (Entity.PUBLISHER, "/cmd", "geometry_msgs__msg/Twist"),
        (Entity.SUBSCRIBER, "/log", "std_msgs__msg/String"),
        (Entity.CLIENT, "/echo", "test_msgs__srv/BasicTypes_Request"),
        (Entity.CLIENT, "/quick", "test_msgs__srv/BasicTypes_Request"),
    ]  # native entries (/native_log, /native_echo) are not announced
    assert link.offers[0][0] == 2  # the request goes first
    assert {b.node_name for b in beacons_on(link)} == {"surface"}
    assert link.channels[1] == discovery_policies(4)[1]
    assert link.channels[2] == discovery_policies(4)[2]


def test_gids_are_the_documented_ones_so_a_restart_announces_the_same(surface_only):
    surface, bridge, link = surface_only
    first = beacons_on(link)[0]
    assert first.gid == derive_gid("fake", "surface", Entity.PUBLISHER, "/cmd")


def test_every_discovery_request_is_answered_with_all_beacons(surface_only):
    surface, bridge, link = surface_only
    before = len(link.offered(1))
    link.inject(encode_discovery_request())
    wait_for(lambda: len(link.offered(1)) == 2 * before, what="a second round of beacons")
    assert beacons_on(link)[before:] == beacons_on(link)[:before]
    assert len(link.offered(2)) == 1   # answering a request does not ask back
    assert bridge.counters.unknown_id == 0


def test_heard_beacons_build_the_remote_graph_shown_in_status(surface_only, caplog):
    surface, bridge, link = surface_only
    caplog.set_level(logging.INFO, logger="uwgen.interop.graph")
    link.inject(remote_beacon())
    link.inject(remote_beacon())                 # announced again: no change
    link.inject(remote_beacon(Entity.SUBSCRIBER, "/cmd", "geometry_msgs__msg/Twist"))
    wait_for(lambda: bridge.discovery.stats()["beacons_heard"] == 3, what="3 beacons heard")
    status = json.loads(json.dumps(bridge.status()))
    remote = status["discovery"]["remote"]
    assert [(e["node"], e["entity"], e["topic"]) for e in remote] == [
        ("/vehicle_app", "subscriber", "/cmd"), ("/vehicle_app", "service", "/reset")]
    assert status["discovery"]["counters"]["graph"]["added"] == 2
    assert [a["topic"] for a in status["discovery"]["announced"]] == [
        "/cmd", "/log", "/echo", "/quick"]
    lines = [r.getMessage() for r in caplog.records if r.name == "uwgen.interop.graph"]
    assert len(lines) == 2 and "added service /reset" in lines[0]  # one line per change
    link.inject(remote_beacon(gone=True))
    wait_for(lambda: len(bridge.status()["discovery"]["remote"]) == 1, what="/reset withdrawn")
    assert bridge.counters.unknown_id == 0


def test_own_beacons_echoed_back_are_not_remote(surface_only):
    surface, bridge, link = surface_only
    for payload in link.offered(1):
        link.inject(payload)
    wait_for(lambda: bridge.discovery.stats()["graph"]["own"] == 4, what="echoes ignored")
    assert bridge.status()["discovery"]["remote"] == []


def test_malformed_beacon_is_counted_not_raised(surface_only):
    surface, bridge, link = surface_only
    link.inject(bytes([0, 1, 0x61, 0x78]))     # kind 0, id 1, then a lone text item
    wait_for(lambda: bridge.discovery.stats()["malformed"] == 1, what="malformed counted")
    assert bridge.status()["discovery"]["remote"] == []


def test_reconnected_link_asks_again_and_announces_again(surface_only):
    surface, bridge, link = surface_only
    beacons = len(link.offered(1))
    link.connects = 2                            # the link reconnected
    wait_for(lambda: len(link.offered(2)) == 2, what="a second discovery request")
    wait_for(lambda: len(link.offered(1)) == 2 * beacons, what="a second round of beacons")
    link.connects = 3
    wait_for(lambda: len(link.offered(2)) == 3, what="a third discovery request")


def test_close_withdraws_every_entity_before_the_link_stops(surface_only):
    surface, bridge, link = surface_only
    announced = beacons_on(link)
    surface.executor.remove_node(bridge)
    bridge.close()
    assert link.stopped and link.offered_after_stop == 0
    gone = beacons_on(link)[len(announced):]
    assert [b.disconnect for b in gone] == [True] * 4
    assert [(b.gid, b.entity, b.topic, b.type_name) for b in gone] == [
        (b.gid, b.entity, "", "") for b in announced]


def test_native_only_bridge_runs_no_discovery():
    package = fake_package([NATIVE_LOG], [NATIVE_ECHO])
    links = LinkPair()
    with ros_sides("surface") as (surface,):
        bridge = start_bridge(surface, package, links.factory)
        link = links.links["surface"]
        assert bridge.discovery is None and bridge.status()["discovery"] is None
        assert 1 not in link.channels and 2 not in link.channels
        link.inject(encode_discovery_request())
        wait_for(lambda: bridge.counters.unknown_id == 1, what="id 2 is just unknown")
        assert link.offers == []


@pytest.mark.parametrize("publisher", ["surface", "vehicle"])
def test_manifest_giving_discovery_ids_to_its_entries_is_refused(publisher):
    clash = FakeTopicCodec(1, "/clash", String, publisher, profile=RMW)
    links = LinkPair()
    with ros_sides("surface") as (surface,):
        with pytest.raises(PlanError, match=r"ids \[1\] are rmw_desert's discovery topics"):
            start_bridge(surface, fake_package([clash]), links.factory)


def test_entries_rclpy_cannot_carry_are_not_announced():
    missing = FakeTopicCodec(9, "/pose", None, "vehicle", profile=RMW)
    links = LinkPair()
    with ros_sides("surface") as (surface,):
        bridge = start_bridge(surface, fake_package([CMD, missing]), links.factory)
        assert "/pose" in bridge.unavailable
        assert [b.topic for b in beacons_on(links.links["surface"])] == ["/cmd"]


def test_two_bridges_in_the_profile_see_each_other():
    package = fake_package([CMD, LOG], [ECHO])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        sb = start_bridge(surface, package, links.factory)
        vb = start_bridge(vehicle, package, links.factory)
        # The vehicle's start-up request reaches the surface, which answers it.
        wait_for(lambda: len(sb.status()["discovery"]["remote"]) == 3, what="vehicle entities")
        remote = {(e["node"], e["entity"], e["topic"]) for e in sb.status()["discovery"]["remote"]}
        assert remote == {("/vehicle", "subscriber", "/cmd"),
                          ("/vehicle", "publisher", "/log"),
                          ("/vehicle", "service", "/echo")}
        vehicle.executor.remove_node(vb)
        vb.close()
        wait_for(lambda: sb.status()["discovery"]["remote"] == [], what="vehicle withdrawn")


# -- unit parts of discovery.py the bridge relies on ------------------------------------

def test_beacons_for_codecs_match_the_bridge_roles():
    beacons = beacons_for("fake", "vehicle", [CMD, LOG, NATIVE_LOG], [ECHO, NATIVE_ECHO])
    assert [(b.entity, b.topic) for b in beacons] == [
        (Entity.SUBSCRIBER, "/cmd"), (Entity.PUBLISHER, "/log"), (Entity.SERVICE, "/echo")]
    assert beacons[2].type_name == "test_msgs__srv/BasicTypes_Response"


def test_agent_announces_nothing_after_stop():
    sent = []
    agent = DiscoveryAgent(beacons_for("fake", "surface", [CMD], []),
                           send=lambda k, p: sent.append(k) or True)
    agent.start()
    agent.stop()
    sent.clear()
    agent.announce(request=True)
    assert sent == []


# -- services toward rmw_desert servers ------------------------------------------------

def request_seqs(link, ident):
    return [load_items(p)[2] for k, p in list(link.offers) if k == ident]


def test_calls_toward_rmw_desert_services_use_seqs_1_to_999(surface_only):
    surface, bridge, link = surface_only
    assert bridge._calls.seq_range(ECHO.id) == (1, 999)
    assert bridge._calls.seq_range(NATIVE_ECHO.id) == (0, 65535)
    client = surface.node("caller").create_client(BasicTypes, "/echo")
    assert client.wait_for_service(timeout_sec=5.0)
    futures = [client.call_async(BasicTypes.Request(int32_value=i)) for i in range(5)]
    wait_for(lambda: len(request_seqs(link, ECHO.id)) == 5, what="5 requests offered")
    seqs = request_seqs(link, ECHO.id)
    assert all(1 <= s <= 999 for s in seqs) and len(set(seqs)) == 5
    for seq in seqs:   # answer all, so the test leaves nothing pending
        link.inject(ECHO.encode_response(seq, BasicTypes.Response(int32_value=seq)))
    wait_for(lambda: all(f.done() for f in futures), what="every response")
    assert [f.result().int32_value for f in futures] == seqs


def test_server_answering_only_the_latest_request(surface_only):
    """Three calls outstanding; the server answers only the newest. The newest caller gets
    its response, the two older calls time out and are counted, and an answer that comes
    late for one of them is counted as late, never handed to anyone."""
    surface, bridge, link = surface_only
    client = surface.node("caller").create_client(BasicTypes, "/quick")
    assert client.wait_for_service(timeout_sec=5.0)
    futures = [client.call_async(BasicTypes.Request(int32_value=i)) for i in range(3)]
    wait_for(lambda: len(request_seqs(link, QUICK.id)) == 3, what="3 requests offered")
    seqs = request_seqs(link, QUICK.id)
    newest = QUICK.decode_request(link.offered(QUICK.id)[-1])[1].int32_value
    link.inject(QUICK.encode_response(seqs[-1], BasicTypes.Response(int32_value=100 + newest)))
    wait_for(lambda: any(f.done() for f in futures), what="the newest response")
    done = [f for f in futures if f.done()]
    assert len(done) == 1 and done[0].result().int32_value == 100 + newest
    counters = bridge.service_counters[QUICK.id]
    wait_for(lambda: counters.timeouts == 2, timeout=5.0, what="the older calls' timeouts")
    link.inject(QUICK.encode_response(seqs[0], BasicTypes.Response(int32_value=-1)))
    calls = lambda: bridge.status()["services"]["/quick"]["calls"]  # noqa: E731
    wait_for(lambda: calls()["late"] == 1, what="the late answer counted")
    assert (calls()["completed"], calls()["timeouts"], calls()["outstanding"]) == (1, 2, 0)
    assert counters.responses == 1
    assert sum(f.done() for f in futures) == 1
    for f in futures:
        if not f.done():
            client.remove_pending_request(f)


@pytest.mark.parametrize("seq", [0, 1, 500, 999])
def test_server_side_echoes_the_request_seq(seq):
    package = fake_package([], [ECHO])
    links = LinkPair()
    with ros_sides("vehicle") as (vehicle,):
        bridge = start_bridge(vehicle, package, links.factory)
        link = links.links["vehicle"]

        def serve(req, resp):
            resp.int32_value = req.int32_value + 1
            return resp
        vehicle.node("server").create_service(BasicTypes, "/echo", serve)
        wait_for(lambda: bridge._served[ECHO.id][1].service_is_ready(), what="local server")
        link.inject(ECHO.encode_request(seq, BasicTypes.Request(int32_value=41)))
        wait_for(lambda: link.offered(ECHO.id), what="the response")
        got_seq, resp = ECHO.decode_response(link.offered(ECHO.id)[0])
        assert (got_seq, resp.int32_value) == (seq, 42)


# -- shutdown ------------------------------------------------------------------------------

def test_subscriptions_are_listed_once_and_close_destroys_everything(surface_only):
    surface, bridge, link = surface_only
    assert len(list(bridge.subscriptions)) == 1      # /cmd, this side's outgoing topic
    surface.executor.remove_node(bridge)
    status = bridge.close()                          # raises if destroy_node fails
    assert status["side"] == "surface"
    assert list(bridge.subscriptions) == [] and list(bridge.services) == []
    assert list(bridge.publishers) == [] and list(bridge.timers) == []
    assert bridge.close() == {}                      # idempotent


def test_final_summary_names_the_remote_graph():
    from uwgen.bridge.main import _summary
    remote = [{"node": "/vehicle_app", "entity": "service", "topic": "/reset"},
              {"node": "/vehicle_app", "entity": "client", "topic": "/arm"}]
    assert _summary({"discovery": {"remote": remote}}).endswith(
        "rmw_desert remote graph: 2 entities of /vehicle_app")
    assert "remote graph" not in _summary({"discovery": None})


def test_close_waits_for_a_stuck_link_only_up_to_its_flush_timeout():
    """A link that never drains its discovery queue does not hold shutdown hostage."""
    from .fakes import FakeLink

    class StuckLink(FakeLink):
        def stats(self):
            stats = super().stats()
            stats["channels"][1]["queued"] = 3
            return stats

    stuck = []

    def factory(**kw):
        stuck.append(StuckLink(**kw))
        return stuck[-1]
    with ros_sides("surface") as (surface,):
        bridge = start_bridge(surface, fake_package([CMD]), factory, flush_timeout=0.05)
        surface.executor.remove_node(bridge)
        bridge.close()
        assert stuck[0].stopped and not bridge._flush_discovery()  # gave up, did not hang
