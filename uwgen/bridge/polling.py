"""Latest-only topics taken by polling while busy, not by one executor wake-up per message.

A latest-only topic keeps only its newest message in the link queue, so every message
the bridge deserializes and encodes but a newer one replaces is CPU spent for nothing,
and on a busy topic (cmd_vel at 1 000 msg/s and more) the executor's wake-up per
message (rebuilding its wait set, taking one message, deserializing it) is most of the
bridge's CPU. So a latest-only topic has two states:

- waiting (idle): the executor waits on its subscription as on any other. When a
  message comes, the bridge takes it and whatever else the subscription holds, and the
  topic turns to
- polling: the executor no longer waits on it; `LatestPoller` takes, every POLL_PERIOD
  seconds, what the subscription holds as raw (serialized) messages. A poll that finds
  nothing turns the topic back to waiting (and with no topic polling, the timer stops:
  an idle bridge is not woken 50 times a second).

Either way every message taken is counted as taken, and only the newest of one take is
deserialized, encoded and offered; the older ones are counted as superseded
(uwgen.runtime.delivery.ledger), as the link queue would have counted them. While polling, a
message waits at most POLL_PERIOD more before it is offered.

How the executor is kept off the subscription without a node of its own: each such
subscription has a `PolledGroup`, a callback group that, while its topic is polling,
never lets the executor run, so never wait on, any of its entities, and otherwise lets
them run as the bridge's main group does. Its QoS event handlers (message lost,
incompatible QoS) are in that group too: the executor handles them while the topic
waits, the poller takes them at each poll while it polls. (With rmw_fastrtps a wait on
any event of a subscription returns at once while the subscription holds a message, so
an executor waiting on them between two polls would spin: a full core at 1 000 msg/s,
measured.) The subscription and its handlers are the bridge node's own, and
destroy_node releases them.

Its history holds POLL_HISTORY messages (or the manifest's depth, if larger): enough
for what arrives between two polls at 50 000 msg/s, so that what is taken is what was
published (a keep-last history overwrites without telling anyone) and the newest is
never lost (a keep-all history at its limit refuses the newest, and may block a reliable
publisher).

FIFO topics stay on executor wake-ups (with burst takes, uwgen.bridge.topics): each of
their messages is kept, so each must be deserialized and encoded anyway, and a poll
period would only add latency to them, often the high-priority ones.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.serialization import deserialize_message

POLL_PERIOD = 0.02    # s between two takes of a busy latest-only topic
POLL_HISTORY = 1000   # messages a polled subscription's history holds (at least)


class PolledGroup(CallbackGroup):
    """The callback group of one latest-only subscription and its event handlers: while
    `polling`, the executor never runs nor waits on any of them (LatestPoller takes from
    them); otherwise they run as those of `main` do, under the same mutual exclusion."""

    def __init__(self, main: CallbackGroup):
        super().__init__()
        self.main = main
        self.polling = False

    def add_entity(self, entity: Any) -> None:
        super().add_entity(entity)
        self.main.add_entity(entity)     # main's mutual exclusion knows it

    def can_execute(self, entity: Any) -> bool:
        return not self.polling and self.main.can_execute(entity)

    def beginning_execution(self, entity: Any) -> bool:
        return not self.polling and self.main.beginning_execution(entity)

    def ending_execution(self, entity: Any) -> None:
        self.main.ending_execution(entity)


def take_events(handlers: list) -> None:
    """Take the QoS events of `handlers` (rclpy EventHandlers that no wait set holds) and
    run the callback of each that changed. rclpy's take_data takes only after a wait said
    the event is ready; without a wait, every event is taken (an unchanged one reads as a
    change of 0, and is not passed on)."""
    for handler in handlers:
        handler._ready_to_take_data = True
        info = handler.take_data()
        if info is not None and getattr(info, "total_count_change", 0) > 0:
            handler.callback(info)


# What a latest-only topic's newest message is handed to: (codec, message, message info).
Send = Callable[[Any, Any, Any], None]


@dataclass
class Polled:
    """One latest-only topic: its codec, subscription, rclpy class and group."""
    codec: Any
    cls: Any
    group: PolledGroup
    sub: Any = None


class LatestPoller:
    """The latest-only subscriptions of a bridge, and the timer that polls the busy ones."""

    def __init__(self, node: Any, main_group: CallbackGroup, send: Send, counters: dict,
                 say_once: Callable[[str, str], None], period: float = POLL_PERIOD):
        self.node, self.send, self.counters, self.say_once = node, send, counters, say_once
        self.main_group, self.period = main_group, period
        self.polled: list[Polled] = []
        self.timer = None

    def subscribe(self, codec: Any, cls: Any, qos: Any, event_callbacks: Any) -> Any:
        """The subscription of latest-only topic `codec` (`qos`: an rclpy profile)."""
        qos.depth = max(qos.depth, POLL_HISTORY)
        topic = Polled(codec, cls, PolledGroup(self.main_group))

        def woken(raw: bytes, info: Any) -> None:   # two arguments: rclpy passes MessageInfo
            self.woken(topic, raw, info)
        topic.sub = self.node.create_subscription(cls, codec.name, woken, qos, callback_group=topic.group,
                                                  event_callbacks=event_callbacks, raw=True)
        self.polled.append(topic)
        if self.timer is None:
            self.timer = self.node.create_timer(self.period, self.poll, callback_group=self.main_group)
            self.timer.cancel()          # started by the first message
        return topic.sub

    def woken(self, topic: Polled, raw: bytes, info: Any) -> None:
        """The executor took a message of a waiting topic: take the rest it holds, and
        poll it from now on."""
        self.take(topic, first=(raw, info))
        topic.group.polling = True
        if self.timer.is_canceled():
            self.timer.reset()

    def poll(self) -> None:
        """Take the QoS events and the messages of every polling topic; send the newest
        message of each. A topic that had none waits again; with none left, the timer stops."""
        busy = [topic for topic in self.polled if topic.group.polling]
        for topic in busy:
            try:
                take_events(topic.sub.event_handlers)
            except Exception as exc:  # noqa: BLE001 - destroyed (shutdown), or rclpy changed
                self.say_once(f"events{topic.codec.id}", f"{topic.codec.name}: cannot take the subscription's "
                                                         f"QoS events (message lost, incompatible QoS): {exc!r}")
            if not self.take(topic):
                topic.group.polling = False
        if busy and not any(topic.group.polling for topic in self.polled):
            self.timer.cancel()

    def take(self, topic: Polled, first: tuple | None = None) -> int:
        """Take what the subscription holds (after `first`, the one the executor took):
        count it all, send the newest. Returns how many were taken."""
        codec, sub = topic.codec, topic.sub
        newest, n = first, 1 if first is not None else 0
        try:
            while n < POLL_HISTORY:    # bounded: a fast publisher cannot keep us here
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, True)
                if got is None:
                    break
                newest, n = got, n + 1
        except Exception as exc:  # noqa: BLE001 - the subscription was destroyed (shutdown)
            self.say_once(f"poll{codec.id}", f"{codec.name}: cannot take from the subscription ({exc!r})")
        if not n:
            return 0
        counters = self.counters[codec.id]
        counters.taken += n
        counters.superseded += n - 1
        try:
            msg = deserialize_message(newest[0], topic.cls)
        except Exception as exc:  # noqa: BLE001 - rclpy could not read what DDS delivered
            counters.encode_errors += 1
            self.say_once(f"deser{codec.id}", f"{codec.name}: message not sent, rclpy cannot "
                                              f"deserialize it: {exc!r}")
            return n
        self.send(codec, msg, newest[1] if len(newest) > 1 else None)
        return n
