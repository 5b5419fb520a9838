"""The bridge node with real rclpy graphs on both sides and a fake link between them."""
from __future__ import annotations

import json
import threading
import time

import pytest
from geometry_msgs.msg import Twist, Vector3
from std_msgs.msg import String
from test_msgs.srv import BasicTypes

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire.codec import load_items, pack_items

from .fakes import (FakeServiceCodec, FakeSubscription, FakeTopicCodec, LinkPair, fake_package,
                    wait_for)
from .harness import ros_sides, start_bridge

CMD = FakeTopicCodec(4, "/cmd", Twist, "surface")
LOG = FakeTopicCodec(7, "/log", String, "vehicle")
ECHO = FakeServiceCodec(20, "/echo", BasicTypes, "vehicle", timeout=5.0)
SLOW = FakeServiceCodec(21, "/slow", BasicTypes, "vehicle", timeout=0.4)


def start_bridges(sides, package, links, **opts):
    return {side.name: start_bridge(side, package, links.factory, **opts) for side in sides}


def collect(node, cls, topic):
    got = []
    node.create_subscription(cls, topic, got.append, 10)
    return got


def echo_server(node, name="/echo") -> list[int]:
    """The real server of `name` on `node`: it answers twice the number and "re:" the text.
    Returns the numbers it is called with, call by call."""
    served: list[int] = []

    def serve(req, resp):
        served.append(req.int32_value)
        resp.int32_value = req.int32_value * 2
        resp.string_value = f"re:{req.string_value}"
        return resp
    node.create_service(BasicTypes, name, serve)
    return served


def served_client(pair, codec=ECHO):
    """A caller of `codec`'s service on the surface, once the vehicle's bridge sees the real
    (echo) server behind it."""
    surface, vehicle, bridges, _ = pair
    echo_server(vehicle.node("server"), codec.name)
    client = surface.node("caller").create_client(BasicTypes, codec.name)
    assert client.wait_for_service(timeout_sec=5.0)
    wait_for(lambda: bridges["vehicle"]._served[codec.id][1].service_is_ready(),
             what="vehicle bridge sees the real server")
    return client


@pytest.fixture
def pair():
    package = fake_package([CMD, LOG], [ECHO, SLOW])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        yield surface, vehicle, bridges, links


def test_topics_cross_in_both_directions(pair):
    surface, vehicle, bridges, links = pair
    cmds = collect(vehicle.node("sim"), Twist, "/cmd")
    logs = collect(surface.node("op"), String, "/log")
    pub_cmd = surface.node("op_pub").create_publisher(Twist, "/cmd", 10)
    pub_log = vehicle.node("sim_pub").create_publisher(String, "/log", 10)
    wait_for(lambda: pub_cmd.get_subscription_count() and pub_log.get_subscription_count(),
             what="bridges subscribed")
    msg = Twist()
    msg.linear.x, msg.angular.z = 2.0, 1.8
    pub_cmd.publish(msg)
    pub_log.publish(String(data="hello surface"))
    wait_for(lambda: cmds and logs, what="messages across")
    assert (cmds[0].linear.x, cmds[0].angular.z) == (2.0, 1.8)
    assert logs[0].data == "hello surface"
    status = bridges["vehicle"].status()
    assert status["topics"]["/cmd"]["published"] == 1
    assert status["topics"]["/log"]["offered"] == 1


def test_received_messages_are_never_sent_back(pair):
    surface, vehicle, bridges, links = pair
    cmds = collect(vehicle.node("sim"), Twist, "/cmd")
    pub = surface.node("op").create_publisher(Twist, "/cmd", 10)
    wait_for(lambda: pub.get_subscription_count(), what="bridge subscribed")
    for k in range(5):
        pub.publish(Twist(linear=Vector3(x=float(k))))
    wait_for(lambda: cmds and cmds[-1].linear.x == 4.0, what="the last command across")
    # The vehicle bridge published /cmd but offered nothing of it to its link. (The
    # surface bridge took all 5; of a burst of a latest-only topic it offers the newest.)
    assert [k for k, _ in links.links["vehicle"].offers if k == CMD.id] == []
    counters = bridges["surface"].topics.counters[CMD.id]
    assert counters.taken == 5 and counters.offered + counters.superseded == 5
    assert len(links.links["surface"].offers) == counters.offered == len(cmds)
    # And it holds no subscription on /cmd, only a publisher.
    vb = bridges["vehicle"]
    subs = dict(vb.get_subscriber_names_and_types_by_node(vb.get_name(), "/"))
    pubs = dict(vb.get_publisher_names_and_types_by_node(vb.get_name(), "/"))
    assert "/cmd" in pubs and "/cmd" not in subs


def test_topics_outside_the_manifest_never_touch_the_link(pair):
    surface, vehicle, bridges, links = pair
    pub = surface.node("op").create_publisher(Twist, "/not_bridged", 10)
    cmd = surface.node("op2").create_publisher(Twist, "/cmd", 10)
    wait_for(lambda: cmd.get_subscription_count(), what="bridge subscribed")
    for _ in range(3):
        pub.publish(Twist())
    cmd.publish(Twist())
    wait_for(lambda: links.links["surface"].offers, what="the /cmd offer")
    assert {k for k, _ in links.links["surface"].offers} == {CMD.id}
    # A payload with an id the manifest does not have is counted, not delivered.
    links.links["vehicle"].inject(pack_items([0, 99, b"x"]))
    wait_for(lambda: bridges["vehicle"].counters.unknown_id == 1, what="unknown id counted")


def test_bad_payloads_are_counted_by_reason(pair):
    surface, vehicle, bridges, links = pair
    vlink = links.links["vehicle"]
    vlink.inject(b"\xff\xff")                         # no header
    vlink.inject(pack_items([0, CMD.id, b"garbage"]))  # right header, fields do not decode
    vlink.inject(pack_items([0, LOG.id, b"x"]))        # a topic the vehicle itself publishes
    vlink.inject(pack_items([2, CMD.id, 1, b"x"]))     # request kind on a topic id
    vb = bridges["vehicle"]
    wait_for(lambda: vb.counters.bad_header and vb.topic_counters[CMD.id].decode_errors
             and vb.counters.wrong_direction and vb.counters.bad_kind, what="all four counted")
    assert vb.topic_counters[CMD.id].published == 0


def test_service_round_trip(pair):
    _, _, bridges, _ = pair
    client = served_client(pair)
    req = BasicTypes.Request(int32_value=21, string_value="hi")
    future = client.call_async(req)
    wait_for(future.done, what="the response")
    assert (future.result().int32_value, future.result().string_value) == (42, "re:hi")
    calls = bridges["surface"].status()["services"]["/echo"]
    assert calls["responses"] == 1 and calls["calls"]["completed"] == 1
    assert bridges["vehicle"].status()["services"]["/echo"]["replies"] == 1


def test_several_outstanding_calls_get_their_own_responses(pair):
    *_, links = pair
    client = served_client(pair)
    links.links["vehicle"].delay = 0.2   # responses wait, so the calls overlap
    futures = [client.call_async(BasicTypes.Request(int32_value=i, string_value=str(i)))
               for i in range(4)]
    wait_for(lambda: all(f.done() for f in futures), what="4 responses")
    assert [f.result().int32_value for f in futures] == [0, 2, 4, 6]
    assert [f.result().string_value for f in futures] == ["re:0", "re:1", "re:2", "re:3"]
    seqs = [load_items(p)[2] for _, p in links.links["surface"].offers]
    assert len(set(seqs)) == 4 and all((b - a) % 65536 == 1 for a, b in zip(seqs, seqs[1:]))


def test_call_without_response_fails_by_sending_no_response(pair):
    surface, vehicle, bridges, links = pair
    client = surface.node("caller").create_client(BasicTypes, "/slow")
    assert client.wait_for_service(timeout_sec=5.0)
    links.links["surface"].mute = True  # the request is lost on the link
    future = client.call_async(BasicTypes.Request())
    sb = bridges["surface"]
    wait_for(lambda: sb.service_counters[SLOW.id].timeouts == 1, what="the timeout")
    # The stand-in sent no response: the caller's own timeout is what detects the failure.
    assert not future.done()
    status = sb.status()["services"]["/slow"]
    assert status["calls"]["timeouts"] == 1 and status["calls"]["outstanding"] == 0
    assert status["responses"] == 0
    client.remove_pending_request(future)


def test_late_response_is_dropped_and_counted(pair):
    _, _, bridges, links = pair
    client = served_client(pair, SLOW)
    links.links["vehicle"].delay = 0.8  # response arrives after the 0.4 s timeout
    future = client.call_async(BasicTypes.Request(int32_value=1))
    sb = bridges["surface"]
    wait_for(lambda: sb.status()["services"]["/slow"]["calls"].get("late") == 1,
             what="late response counted")
    assert not future.done()
    assert sb.service_counters[SLOW.id].timeouts == 1
    client.remove_pending_request(future)


def test_duplicate_response_is_dropped_and_counted(pair):
    _, _, bridges, links = pair
    client = served_client(pair)
    links.links["vehicle"].duplicate = True
    future = client.call_async(BasicTypes.Request(int32_value=5))
    sb = bridges["surface"]
    # the bridge counts the second copy on the link's thread; the caller's executor may not
    # have taken the first one's response yet
    wait_for(lambda: sb.status()["services"]["/echo"]["calls"].get("duplicate") == 1
             and future.done(), what="duplicate counted and the call answered")
    assert future.result().int32_value == 10
    assert sb.service_counters[ECHO.id].responses == 1


def test_timeout_reply_default_returns_a_default_response():
    package = fake_package([CMD], [SLOW])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links, timeout_reply="default")
        client = surface.node("caller").create_client(BasicTypes, "/slow")
        assert client.wait_for_service(timeout_sec=5.0)
        links.links["surface"].mute = True
        future = client.call_async(BasicTypes.Request(int32_value=3))
        wait_for(future.done, what="the default response")
        assert future.result() == BasicTypes.Response()
        assert bridges["surface"].service_counters[SLOW.id].timeouts == 1


def test_request_without_local_server_is_counted(pair):
    surface, vehicle, bridges, links = pair
    client = surface.node("caller").create_client(BasicTypes, "/slow")
    assert client.wait_for_service(timeout_sec=5.0)
    client.call_async(BasicTypes.Request())
    vb = bridges["vehicle"]
    wait_for(lambda: vb.service_counters[SLOW.id].no_server == 1, what="no_server counted")
    wait_for(lambda: bridges["surface"].service_counters[SLOW.id].timeouts == 1,
             what="the caller's timeout")


def test_request_that_comes_before_the_server_is_discovered_waits_for_it(pair):
    surface, vehicle, bridges, links = pair
    client = surface.node("caller").create_client(BasicTypes, "/echo")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(BasicTypes.Request(int32_value=21, string_value="first"))
    vb = bridges["vehicle"]
    wait_for(lambda: vb.service_counters[ECHO.id].waited == 1, what="the request waiting")
    echo_server(vehicle.node("late_server"))          # the real server comes up only now
    wait_for(future.done, what="the first call's response")
    assert future.result().int32_value == 42 and future.result().string_value == "re:first"
    assert vb.service_counters[ECHO.id].no_server == 0
    assert bridges["surface"].service_counters[ECHO.id].timeouts == 0


def lose_next(link, kind: int, count: int = 1) -> list:
    """Make `link` lose its next `count` payloads of `kind`; returns what it lost."""
    lost, offer = [], link.offer

    def lossy(key, payload, **kw):          # kw: published (a copy keeps its call's)
        if payload[0] == kind and len(lost) < count:
            lost.append(payload)
            return True
        return offer(key, payload, **kw)
    link.offer = lossy
    return lost


@pytest.mark.parametrize("side, kind", [("surface", 2), ("vehicle", 3)],
                         ids=["request lost", "response lost"])
def test_a_call_whose_request_or_response_is_lost_is_served_once(pair, side, kind):
    surface, vehicle, bridges, links = pair
    served = echo_server(vehicle.node("server"))
    vb = bridges["vehicle"]
    wait_for(lambda: vb._served[ECHO.id][1].service_is_ready(), what="server visible")
    lost = lose_next(links.links[side], kind)
    client = surface.node("caller").create_client(BasicTypes, "/echo")
    assert client.wait_for_service(timeout_sec=5.0)
    future = client.call_async(BasicTypes.Request(int32_value=4))
    wait_for(future.done, what="the response after a resend")
    assert future.result().int32_value == 8 and served == [4] and len(lost) == 1
    assert bridges["surface"].service_counters[ECHO.id].request_resends >= 1
    if kind == 3:
        assert vb.service_counters[ECHO.id].repeated_replies == 1


def test_encode_error_is_counted_and_nothing_is_sent():
    tight = FakeTopicCodec(4, "/cmd", String, "surface", policy=LinkPolicy(queue="fifo", depth=4), max_len=20)
    package = fake_package([tight])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        pub = surface.node("op").create_publisher(String, "/cmd", 10)
        wait_for(lambda: pub.get_subscription_count(), what="bridge subscribed")
        pub.publish(String(data="x" * 100))
        pub.publish(String(data="ok"))
        sb = bridges["surface"]
        wait_for(lambda: sb.topic_counters[4].taken == 2, what="both taken")
        assert sb.topic_counters[4].encode_errors == 1
        assert sb.topic_counters[4].offered == 1


def test_refused_offer_is_counted():
    package = fake_package([CMD])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        links.links["surface"].accept = False
        pub = surface.node("op").create_publisher(Twist, "/cmd", 10)
        wait_for(lambda: pub.get_subscription_count(), what="bridge subscribed")
        pub.publish(Twist())
        wait_for(lambda: bridges["surface"].topic_counters[4].refused == 1, what="refusal counted")


class PlainPose:
    """What a generated package hands out when rclpy has no class for the type."""


def test_type_without_rclpy_class_is_reported_not_bridged():
    missing = FakeTopicCodec(9, "/pose", None, "vehicle")
    plain = FakeTopicCodec(10, "/plain", PlainPose, "surface")
    package = fake_package([CMD, missing, plain])
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        status = bridges["surface"].status()
        assert "not importable" in status["topics"]["/pose"]["unavailable"]
        assert "_TYPE_SUPPORT" in status["topics"]["/plain"]["unavailable"]
        assert "unavailable" not in status["topics"]["/cmd"]


def test_bridges_sharing_one_graph_do_not_loop():
    """Both sides in one ROS domain: the receiving bridge's publication reaches the sending
    bridge's subscription. The guard must stop it from going back over the link."""
    package = fake_package([CMD])
    links = LinkPair()
    with ros_sides("surface", "vehicle", same_domain=True) as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        sb = bridges["surface"]
        wait_for(lambda: "/cmd" in sb.echo_hazards, what="the echo hazard detected")
        pub = surface.node("op").create_publisher(Twist, "/cmd", 10)
        wait_for(lambda: pub.get_subscription_count(), what="bridge subscribed")
        offered = sb.topic_counters[4].offered
        pub.publish(Twist())
        wait_for(lambda: sb.topic_counters[4].taken >= 1, what="message taken")
        assert sb.topic_counters[4].offered == offered
        assert sb.status()["topics"]["/cmd"]["echo_guard"] >= 1


def test_bridges_sharing_one_graph_run_a_call_once():
    """Both sides and the real server in one ROS domain: the serving bridge's client would
    reach the calling bridge's stand-in, and each call would go round between them."""
    package = fake_package([], [ECHO])
    links = LinkPair()
    with ros_sides("surface", "vehicle", same_domain=True) as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        served = echo_server(vehicle.node("real"))
        sb, vb = bridges["surface"], bridges["vehicle"]
        wait_for(lambda: "/echo" in sb.status()["echo_hazards"] and ECHO.id not in sb.standins.services,
                 what="the stand-in withdrawn")
        client = surface.node("caller").create_client(BasicTypes, "/echo")
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(BasicTypes.Request(int32_value=5))
        wait_for(future.done, what="the real server's response")
        assert future.result().int32_value == 10
        time.sleep(0.5)
        assert served == [5] and vb.service_counters[ECHO.id].requests == 0
        assert links.links["surface"].offered(ECHO.id) == []     # nothing went over the link


def test_a_call_answered_after_its_stand_in_was_withdrawn_keeps_the_bridge_running():
    """A call waits for its response over the link while another bridge's client of the
    service appears in this ROS graph: the stand-in is withdrawn (loops.py). The response
    that comes then cannot reach its caller; it is counted and dropped, and the bridge goes
    on: once the other bridge is gone the stand-in returns and the next call is answered."""
    package = fake_package([], [ECHO])
    links = LinkPair()
    release = threading.Event()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), package, links)
        sb = bridges["surface"]

        def held(req, resp):                   # the first call waits for `release`
            release.wait(10.0 if req.int32_value == 1 else 0.0)
            resp.int32_value = req.int32_value * 2
            return resp
        vehicle.node("real").create_service(BasicTypes, "/echo", held)
        client = surface.node("caller").create_client(BasicTypes, "/echo")
        assert client.wait_for_service(timeout_sec=5.0)
        first = client.call_async(BasicTypes.Request(int32_value=1))
        wait_for(lambda: links.links["surface"].offered(ECHO.id), what="the request sent")
        intruder = surface.node("uwgen_bridge_intruder")
        intruder.create_client(BasicTypes, "/echo")
        wait_for(lambda: ECHO.id not in sb.standins.services, what="the stand-in withdrawn")
        release.set()
        wait_for(lambda: sb.service_counters[ECHO.id].answer_withdrawn == 1,
                 what="the response counted, not delivered")
        surface.nodes.remove(intruder)
        surface.executor.remove_node(intruder)
        intruder.destroy_node()
        wait_for(lambda: ECHO.id in sb.standins.services, timeout=10.0, what="the stand-in back")
        assert client.wait_for_service(timeout_sec=5.0)
        second = client.call_async(BasicTypes.Request(int32_value=4))
        wait_for(second.done, what="the next call answered")
        assert second.result().int32_value == 8 and not first.done()
        assert surface._thread.is_alive()


def test_status_is_published_as_json(pair):
    surface, vehicle, bridges, links = pair
    got = collect(surface.node("watch"), String, f"/{bridges['surface'].get_name()}/status")
    bridges["surface"].publish_status()
    wait_for(lambda: got, what="a status message")
    status = json.loads(got[0].data)
    assert status["side"] == "surface" and "/cmd" in status["topics"]
    assert status["topics"]["/cmd"]["direction"] == "out"
    assert status["services"]["/echo"]["role"] == "client"


def twists(*xs):
    return [Twist(linear=Vector3(x=float(x))) for x in xs]


def test_a_burst_on_a_fifo_topic_offers_every_message_in_order():
    fifo = FakeTopicCodec(9, "/fifo", Twist, "surface", policy=LinkPolicy(queue="fifo", depth=8))
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = start_bridges((surface, vehicle), fake_package([fifo]), links)
        topics = bridges["surface"].topics
        first, *more = twists(1, 2, 3)
        topics._subscription_of[fifo.id] = FakeSubscription(more, Twist, fifo.name, raw=False)
        topics._taker(fifo)(first, {})
        assert [p for k, p in links.links["surface"].offers if k == fifo.id] == \
            [fifo.encode(m) for m in (first, *more)]
        counters = topics.counters[fifo.id]
        assert (counters.taken, counters.superseded, counters.offered) == (3, 0, 3)
