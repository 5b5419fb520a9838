"""Latest-only topics taken by polling, not by one executor wake-up per message.

A latest-only topic keeps only its newest message in the link queue, so every message
the bridge deserializes and encodes but a newer one replaces is CPU spent for nothing,
and on a busy topic (cmd_vel at 1 000 msg/s and more) the executor's wake-up per
message (rebuilding its wait set, taking one message, deserializing it) is most of the
bridge's CPU. So the bridge's subscription of a latest-only topic is never waited on:
`LatestPoller` takes, every POLL_PERIOD seconds, what the subscription holds as raw
(serialized) messages, counts them all as taken, and deserializes, encodes and offers
only the newest; the older ones are counted as superseded (uwgen.bridge.ledger), as the
link queue would have counted them.

How the executor is kept off the subscription without a node of its own: the
subscription belongs to a `PolledGroup`, a callback group that never lets the executor
run, so never wait on, any of its entities. Its QoS event handlers (message lost,
incompatible QoS) are in that group too, and taken at each poll as well: with
rmw_fastrtps a wait on any event of a subscription returns at once while the
subscription holds a message, so an executor waiting on them would spin between two
polls (a full core at 1 000 msg/s, measured). The subscription and its handlers are the
bridge node's own, and destroy_node releases them.

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

from typing import Any, Callable

from rclpy.callback_groups import CallbackGroup
from rclpy.serialization import deserialize_message

POLL_PERIOD = 0.02    # s between two takes of the latest-only topics
POLL_HISTORY = 1000   # messages a polled subscription's history holds (at least)


class PolledGroup(CallbackGroup):
    """The callback group of polled subscriptions and their event handlers: the executor
    never runs nor waits on any of them (LatestPoller takes from them)."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


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


# What a polled topic's newest message is handed to: (codec, message, message info).
Send = Callable[[Any, Any, Any], None]


class LatestPoller:
    """The polled subscriptions of a bridge, and the timer that takes from them."""

    def __init__(self, node: Any, main_group: CallbackGroup, send: Send, counters: dict,
                 say_once: Callable[[str, str], None], period: float = POLL_PERIOD):
        self.node, self.send, self.counters, self.say_once = node, send, counters, say_once
        self.group = PolledGroup()
        self.main_group, self.period = main_group, period
        self.polled: list[tuple[Any, Any, Any]] = []   # (codec, subscription, rclpy class)
        self.timer = None

    def subscribe(self, codec: Any, cls: Any, qos: Any, event_callbacks: Any) -> Any:
        """The polled subscription of latest-only topic `codec` (`qos`: an rclpy profile)."""
        qos.depth = max(qos.depth, POLL_HISTORY)
        sub = self.node.create_subscription(cls, codec.name, lambda _raw: self.poll(), qos,
                                            callback_group=self.group, event_callbacks=event_callbacks,
                                            raw=True)
        self.polled.append((codec, sub, cls))
        if self.timer is None:
            self.timer = self.node.create_timer(self.period, self.poll, callback_group=self.main_group)
        return sub

    def poll(self) -> None:
        """Take the QoS events and the messages of every polled subscription; send the
        newest message of each."""
        for codec, sub, cls in self.polled:
            try:
                take_events(sub.event_handlers)
            except Exception as exc:  # noqa: BLE001 - destroyed (shutdown), or rclpy changed
                self.say_once(f"events{codec.id}", f"{codec.name}: cannot take the subscription's "
                                                   f"QoS events (message lost, incompatible QoS): {exc!r}")
            self.take(codec, sub, cls)

    def take(self, codec: Any, sub: Any, cls: Any) -> None:
        newest, n = None, 0
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
            return
        counters = self.counters[codec.id]
        counters.taken += n
        counters.superseded += n - 1
        try:
            msg = deserialize_message(newest[0], cls)
        except Exception as exc:  # noqa: BLE001 - rclpy could not read what DDS delivered
            counters.encode_errors += 1
            self.say_once(f"deser{codec.id}", f"{codec.name}: message not sent, rclpy cannot "
                                              f"deserialize it: {exc!r}")
            return
        self.send(codec, msg, newest[1] if len(newest) > 1 else None)
