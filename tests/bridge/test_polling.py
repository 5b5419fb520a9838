"""Latest-only topics are polled (uwgen.bridge.polling): the newest wins, every message
is counted, QoS events still reach the books, and nothing is left behind at shutdown."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
from geometry_msgs.msg import Twist, Vector3
from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from uwgen.bridge.polling import POLL_HISTORY, PolledGroup, take_events
from uwgen.manifest.model import LinkPolicy

from .fakes import FakeSubscription, FakeTopicCodec, LinkPair, fake_package, wait_for
from .harness import ros_sides, start_bridge

CMD = FakeTopicCodec(4, "/cmd", Twist, "surface")                       # latest-only
LOG = FakeTopicCodec(7, "/log", String, "surface", policy=LinkPolicy(queue="fifo", depth=8))


@pytest.fixture
def surface():
    links = LinkPair()
    with ros_sides("surface") as (side,):
        bridge = start_bridge(side, fake_package([CMD, LOG]), links.factory)
        yield side, bridge, links.links["surface"]


def twist(x: float) -> Twist:
    return Twist(linear=Vector3(x=float(x)))


def test_a_busy_latest_only_topic_is_polled_and_an_idle_one_waited_on(surface):
    side, bridge, link = surface
    by_topic = {s.topic_name: s for s in bridge.topics.subscriptions}
    polled, fifo = by_topic["/cmd"], by_topic["/log"]
    group, timer = polled.callback_group, bridge.topics.poller.timer
    assert isinstance(group, PolledGroup) and fifo.callback_group is not group
    assert polled.qos_profile.depth >= POLL_HISTORY   # what arrives between polls is all taken
    # Idle: the executor waits on it, and no poll timer wakes the bridge.
    assert group.can_execute(polled) and timer.is_canceled()
    # A message wakes the executor once; from then on the topic is polled...
    pub = side.node("op").create_publisher(Twist, "/cmd", 10)
    wait_for(pub.get_subscription_count, what="the bridge subscribed")
    states = []
    bridge.topics.poller.woken = record_state(bridge.topics.poller.woken, group, timer, states)
    pub.publish(twist(1))
    wait_for(lambda: states, what="the executor woken by the message")
    assert states[0] == (True, False)          # polling, timer running, right after the take
    assert not group.can_execute(polled) and not group.beginning_execution(polled)
    # ... until a poll finds nothing: waiting again, the timer stopped.
    wait_for(lambda: not group.polling and timer.is_canceled(), what="back to waiting")
    assert link.offered(CMD.id) == [CMD.encode(twist(1))]
    pub.publish(twist(2))
    wait_for(lambda: len(link.offered(CMD.id)) == 2, what="the next message, after waiting again")
    assert len(states) == 2


def record_state(woken, group, timer, states):
    def recorded(topic, raw, info):
        woken(topic, raw, info)
        states.append((group.polling, timer.is_canceled()))
    return recorded


def test_no_node_but_the_bridge_joins_the_graph(surface):
    side, bridge, _link = surface
    watcher = side.node("watcher")
    name = bridge.get_name()
    wait_for(lambda: name in watcher.get_node_names(), what="the bridge in the graph")
    # (The experiment before it took from a node of its own, `<bridge>_take`.)
    assert [n for n in watcher.get_node_names() if n.startswith(name)] == [name]
    subs = watcher.get_subscriptions_info_by_topic("/cmd")
    assert [s.node_name for s in subs if s.node_name.startswith(name)] == [name]


def test_a_burst_between_two_polls_offers_only_the_newest_and_books_the_rest(surface):
    side, bridge, link = surface
    side.executor.remove_node(bridge)              # no timer poll races the ones below
    poller = bridge.topics.poller
    burst = [twist(x) for x in (1, 2, 3, 4)]
    topic = poller.polled[0]
    topic.sub, topic.group.polling = FakeSubscription(burst, Twist, CMD.name, raw=True), True
    poller.poll()
    counters = bridge.topics.counters[CMD.id]
    assert (counters.taken, counters.superseded, counters.offered) == (4, 3, 1)
    assert link.offered(CMD.id) == [CMD.encode(burst[-1])]
    poller.poll()                                  # nothing new: nothing offered, waiting again
    assert link.offered(CMD.id) == [CMD.encode(burst[-1])]
    assert not topic.group.polling
    acc = bridge.status()["topics"]["/cmd"]["accounting"]
    assert (acc["taken"], acc["dropped_by_policy"]["superseded"]) == (4, 3)


def test_a_take_on_wake_up_counts_the_message_the_executor_took(surface):
    side, bridge, link = surface
    side.executor.remove_node(bridge)
    poller = bridge.topics.poller
    first, *more = [twist(x) for x in (1, 2, 3)]
    topic = poller.polled[0]
    topic.sub = FakeSubscription(more, Twist, CMD.name, raw=True)
    poller.woken(topic, serialize_message(first), {})
    counters = bridge.topics.counters[CMD.id]
    assert (counters.taken, counters.superseded, counters.offered) == (3, 2, 1)
    assert link.offered(CMD.id) == [CMD.encode(more[-1])] and topic.group.polling


def test_the_newest_published_message_is_the_last_one_offered(surface):
    side, bridge, link = surface
    pub = side.node("op").create_publisher(Twist, "/cmd", 10)
    wait_for(pub.get_subscription_count, what="the bridge subscribed")
    for x in range(50):
        pub.publish(twist(x))
    counters = bridge.topics.counters[CMD.id]
    wait_for(lambda: counters.taken == 50, what="all 50 taken")
    wait_for(lambda: counters.offered + counters.superseded == 50, what="all 50 booked")
    assert link.offered(CMD.id)[-1] == CMD.encode(twist(49))
    assert len(link.offered(CMD.id)) == counters.offered


def test_qos_events_of_a_polled_subscription_are_taken_by_the_poller(surface):
    side, bridge, _link = surface
    # A best-effort publisher cannot serve the bridge's reliable subscription: an
    # incompatible-QoS event. While the topic polls, no executor waits on it: the poller
    # takes it.
    side.executor.remove_node(bridge)
    poller = bridge.topics.poller
    poller.polled[0].group.polling = True
    side.node("op").create_publisher(Twist, "/cmd", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))

    def counted():
        poller.poll()
        poller.polled[0].group.polling = True
        return bridge.status()["topics"]["/cmd"]["qos_incompatible"] >= 1
    wait_for(counted, what="the incompatible-QoS event counted")
    # Message-lost events are taken the same way, and booked as dropped by the subscription.
    polled = next(s for s in bridge.topics.subscriptions if s.topic_name == "/cmd")
    lost = next(h for h in polled.event_handlers
                if h.event_type == QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)
    assert not lost.callback_group.can_execute(lost)      # not in the executor's wait set now
    lost.callback(SimpleNamespace(total_count=3, total_count_change=3))
    acc = bridge.status()["topics"]["/cmd"]["accounting"]
    assert acc["dropped_by_subscription"] == 3 and acc["published"] == acc["taken"] + 3


class FakeEventHandler:
    """An rclpy EventHandler as take_events uses it: take_data only once a wait said ready."""

    def __init__(self, change):
        self.change, self.seen, self._ready_to_take_data = change, [], False

    def take_data(self):
        if not self._ready_to_take_data:
            return None
        self._ready_to_take_data = False
        return SimpleNamespace(total_count=self.change, total_count_change=self.change)

    def callback(self, info):
        self.seen.append(info.total_count_change)


def test_take_events_passes_on_changed_events_only():
    quiet, lossy = FakeEventHandler(0), FakeEventHandler(2)
    take_events([quiet, lossy])
    assert (quiet.seen, lossy.seen) == ([], [2])


def test_close_leaves_no_subscription_and_stops_polling(surface):
    side, bridge, link = surface
    watcher = side.node("watcher")
    pub = watcher.create_publisher(Twist, "/cmd", 10)
    wait_for(pub.get_subscription_count, what="the bridge subscribed")
    name, timer = bridge.get_name(), bridge.topics.poller.timer
    side.executor.remove_node(bridge)
    bridge.close()
    wait_for(lambda: not watcher.get_subscriptions_info_by_topic("/cmd"), what="the subscription gone")
    wait_for(lambda: name not in watcher.get_node_names(), what="the bridge gone from the graph")
    assert timer not in list(bridge.timers) and list(bridge.subscriptions) == []
    pub.publish(twist(1))
    bridge.topics.poller.poll()                    # a late poll takes nothing, raises nothing
    assert bridge.topics.counters[CMD.id].taken == 0 and link.offered(CMD.id) == []
