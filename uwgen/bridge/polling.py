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
run (so never wait on) a subscription, and lets everything else in it run as the
bridge's main group does. The subscription's QoS event handlers (message lost,
incompatible QoS) are in that group too, so they are still waited on and counted; the
subscription and its handlers are the bridge node's own, destroyed with it.

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
from rclpy.subscription import Subscription

POLL_PERIOD = 0.02    # s between two takes of the latest-only topics
POLL_HISTORY = 1000   # messages a polled subscription's history holds (at least)


class PolledGroup(CallbackGroup):
    """A callback group whose subscriptions the executor never runs nor waits on; its
    other entities (the subscriptions' event handlers) run as those of `main` do, under
    the same mutual exclusion."""

    def __init__(self, main: CallbackGroup):
        super().__init__()
        self.main = main

    def add_entity(self, entity: Any) -> None:
        super().add_entity(entity)
        self.main.add_entity(entity)     # main's mutual exclusion knows it

    def can_execute(self, entity: Any) -> bool:
        return not isinstance(entity, Subscription) and self.main.can_execute(entity)

    def beginning_execution(self, entity: Any) -> bool:
        return not isinstance(entity, Subscription) and self.main.beginning_execution(entity)

    def ending_execution(self, entity: Any) -> None:
        self.main.ending_execution(entity)


# What a polled topic's newest message is handed to: (codec, message, message info).
Send = Callable[[Any, Any, Any], None]


class LatestPoller:
    """The polled subscriptions of a bridge, and the timer that takes from them."""

    def __init__(self, node: Any, main_group: CallbackGroup, send: Send, counters: dict,
                 say_once: Callable[[str, str], None], period: float = POLL_PERIOD):
        self.node, self.send, self.counters, self.say_once = node, send, counters, say_once
        self.group = PolledGroup(main_group)
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
        """Take what every polled subscription holds; send the newest of each."""
        for codec, sub, cls in self.polled:
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
