"""Bridged topics of one side: local subscriptions that send, publishers of what arrives.

Loops. A topic is outgoing (subscribed) on its publishing side only and incoming
(published) everywhere else, so no bridge holds both a subscription and a publisher of
one topic and none can take its own publication (rclpy's MessageInfo carries no
publisher gid in Jazzy, so a per-message filter is not possible). The remaining hazard is
two bridges of the same network sharing one ROS graph (same ROS_DOMAIN_ID): the
receiving bridge's publications would reach the sending bridge's subscription and go
back over the link. `check_graph()` watches the outgoing topics for publishers that
belong to another uwgen bridge node and, while one exists, drops (and counts as
`echo_guard`) what is taken on that topic, with one error in the log. Run each side in
its own domain.
"""
from __future__ import annotations

from dataclasses import asdict
from typing import Any, Callable

from uwgen.runtime.delivery import ledger
from uwgen.bridge.counters import TopicCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.loops import BRIDGE_NODE_PREFIX
from uwgen.bridge.polling import LatestPoller
from uwgen.bridge.wiring import Wiring, qos_profile
from uwgen.runtime.clock import source_time
from uwgen.runtime.wire.codec import KIND_TOPIC

DRAIN_BATCH = 256     # most messages one subscription callback takes in one go


MAX_AGE_TRUSTED = 3600.0   # s: a source stamp older than this is not a publication time


def publication_time(info: Any, now: float, wall: float) -> float | None:
    """When a taken message was published, on the bridge's clock (`now` is that clock's
    reading, `wall` the system clock's, both at take): from the message info's
    `source_timestamp` (ns since the epoch, stamped by the publisher's rmw on this
    machine's system clock). None when there is none, or it is in the future or older
    than MAX_AGE_TRUSTED (a publisher on another clock): then the ttl runs from now."""
    stamp = source_time(info)
    if stamp is None:
        return None
    age = wall - stamp
    if not 0.0 <= age <= MAX_AGE_TRUSTED:
        return None
    return now - age



def is_latest(codec: Any) -> bool:
    """Whether the link keeps only the newest message of this topic."""
    return getattr(codec.policy, "queue", "latest") == "latest"


class TopicBridge:
    def __init__(self, wiring: Wiring, outgoing: list[Any], incoming: list[Any]):
        self.w = wiring
        self.outgoing_codecs, self.incoming_codecs = outgoing, incoming
        self.counters: dict[int, TopicCounters] = {}
        self.echo_hazards: dict[str, str] = {}         # outgoing topic -> foreign bridge node
        self.echo_dropped: dict[int, int] = {}
        self.outgoing: dict[int, Any] = {}              # id -> codec
        self.incoming: dict[int, tuple[Any, Any]] = {}  # id -> (codec, publisher)
        # Not `_subscriptions`: that is rclpy Node's own list, which destroy_node() empties.
        self.subscriptions: list[Any] = []
        self.sub_losses = ledger.SubscriptionLosses(warn=wiring.log.warning)
        self._subscription_of: dict[int, Any] = {}
        # Latest-only topics are polled (uwgen.bridge.polling), the others taken on wake-ups.
        self.poller = LatestPoller(wiring.node, wiring.main_group, self._send_newest, self.counters,
                                   wiring.say_once)
        node = wiring.node
        rec = wiring.recorder
        for codec in outgoing:
            self.counters[codec.id] = TopicCounters()
            cls = wiring.ros_class(codec)
            if cls is None:
                continue
            if rec is not None:
                rec.topic(codec.name, cls)
            self.outgoing[codec.id] = codec
            qos = qos_profile(ledger.subscription_qos(codec))
            events = self.sub_losses.callbacks(codec.id, codec.name)
            if is_latest(codec):
                sub = self.poller.subscribe(codec, cls, qos, events)
            else:
                sub = node.create_subscription(cls, codec.name, self._taker(codec), qos,
                                               callback_group=wiring.main_group, event_callbacks=events)
            self.subscriptions.append(sub)
            self._subscription_of[codec.id] = sub
        for codec in incoming:
            self.counters[codec.id] = TopicCounters()
            cls = wiring.ros_class(codec)
            if cls is None:
                continue
            if rec is not None:
                rec.topic(codec.name, cls)
            self.incoming[codec.id] = (codec, node.create_publisher(cls, codec.name,
                                                                    qos_profile(codec.qos)))

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in self.incoming:
            dispatcher.route(KIND_TOPIC, ident, self.publish)
        for ident in self.outgoing:
            dispatcher.sends(KIND_TOPIC, ident)

    # -- outgoing ----------------------------------------------------------------------

    def _send_newest(self, codec: Any, msg: Any, info: Any) -> None:
        """What the poller took newest of a latest-only topic."""
        self._send(codec, self.counters[codec.id], msg, info)

    def _taker(self, codec: Any) -> Callable[[Any, Any], None]:
        """The subscription's callback (fifo topics; latest-only ones are polled). It
        takes, in the same call, what else the subscription already holds (up to
        DRAIN_BATCH): one executor wake-up per burst, not per message. Each is offered."""
        counters = self.counters[codec.id]

        def take(msg: Any, info: Any) -> None:    # two arguments: rclpy passes MessageInfo
            sub = self._subscription_of.get(codec.id)
            batch = [(msg, info), *self._more(sub)] if sub is not None else [(msg, info)]
            counters.taken += len(batch)
            for m, minfo in batch:
                self._send(codec, counters, m, minfo)
        return take

    def _more(self, sub: Any) -> list[tuple[Any, Any]]:
        """(message, message info) the subscription holds now (rclpy's own take, as its
        executor does)."""
        out: list[tuple[Any, Any]] = []
        try:
            while len(out) < DRAIN_BATCH:
                with sub.handle:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
                if got is None:
                    break
                out.append((got[0], got[1] if len(got) > 1 else None))
        except Exception as exc:  # noqa: BLE001 - the subscription is going away, or rclpy changed:
            self.w.say_once(f"drain{sub.topic_name}",   # the executor still takes one at a time
                            f"{sub.topic_name}: cannot take queued messages in a batch ({exc!r})")
        return out

    def _send(self, codec: Any, counters: TopicCounters, msg: Any, info: Any) -> None:
        published = publication_time(info, self.w.clock.now(), self.w.wall())
        if self.echo_hazards and self._echo_blocked(codec):
            return
        try:
            payload = codec.encode(msg)
        except ValueError as exc:  # EncodeError: bounds, ranges, too long for the profile
            counters.encode_errors += 1
            self.w.say_once(f"enc{codec.id}{type(exc).__name__}",
                            f"{codec.name}: message not sent, cannot encode: {exc}")
            return
        if self.w.recorder is not None:
            self.w.recorder.message(codec.name, msg, payload, source_time(info))
        if self.w.send(codec.id, payload, published=published):
            counters.offered += 1
        else:
            counters.refused += 1

    def _echo_blocked(self, codec: Any) -> bool:
        if codec.name in self.echo_hazards:
            self.echo_dropped[codec.id] = self.echo_dropped.get(codec.id, 0) + 1
            return True
        return False

    def check_graph(self) -> None:
        """Find other uwgen bridges publishing our outgoing topics in this ROS graph."""
        node, log = self.w.node, self.w.log
        me = (node.get_name(), node.get_namespace())
        for codec in self.outgoing.values():
            try:
                infos = node.get_publishers_info_by_topic(codec.name)
            except Exception:  # the context is shutting down
                return
            foreign = sorted({i.node_name for i in infos
                              if i.node_name.startswith(BRIDGE_NODE_PREFIX)
                              and (i.node_name, i.node_namespace) != me})
            if foreign and codec.name not in self.echo_hazards:
                self.echo_hazards[codec.name] = foreign[0]
                log.error(
                    f"{codec.name}: bridge node {foreign[0]} publishes this topic in the same ROS "
                    f"graph, so what it receives would be sent back over the link; not sending "
                    f"{codec.name} until it is gone (give each side its own ROS_DOMAIN_ID)")
            elif not foreign and codec.name in self.echo_hazards:
                del self.echo_hazards[codec.name]
                log.info(f"{codec.name}: no other bridge publishes it any more; sending again")

    # -- incoming ----------------------------------------------------------------------

    def publish(self, ident: int, payload: bytes) -> None:
        codec, pub = self.incoming[ident]
        counters = self.counters[ident]
        counters.received += 1
        try:
            msg = codec.decode(payload)
        except ValueError as exc:  # DecodeError
            counters.decode_errors += 1
            self.w.say_once(f"dec{ident}", f"{codec.name}: payload dropped, does not decode: {exc}")
            return
        try:
            pub.publish(msg)
        except Exception as exc:  # a type mismatch between codec and rclpy class
            counters.publish_errors += 1
            self.w.say_once(f"pub{ident}", f"{codec.name}: cannot publish decoded message: {exc}")
            return
        counters.published += 1
        if self.w.recorder is not None:
            self.w.recorder.message(codec.name, msg, payload, listeners=pub.get_subscription_count())

    # -- status ------------------------------------------------------------------------

    def status(self, channels: dict[int, dict], link_lost: dict[int, int] | None = None) -> dict[str, dict]:
        """Per topic: the counters, and the `accounting` that adds up (uwgen.runtime.delivery.ledger);
        `link_lost`: messages the link knows were lost, by id."""
        link_lost = link_lost or {}
        topics = {}
        out_ids = {c.id for c in self.outgoing_codecs}
        for codec in (*self.outgoing_codecs, *self.incoming_codecs):
            out = codec.id in out_ids
            entry = {"id": codec.id, "type": codec.type_name,
                     "direction": "out" if out else "in", **asdict(self.counters[codec.id])}
            if out:
                entry["echo_guard"] = self.echo_dropped.get(codec.id, 0)
                entry["qos_incompatible"] = self.sub_losses.incompatible.get(codec.id, 0)
                entry["link"] = channels.get(codec.id, {})
            entry["accounting"] = (ledger.outgoing(self.counters[codec.id], channels.get(codec.id, {}),
                                                   self.sub_losses.lost.get(codec.id, 0),
                                                   self.echo_dropped.get(codec.id, 0)) if out
                                   else ledger.incoming(self.counters[codec.id], link_lost.get(codec.id, 0)))
            if codec.name in self.w.unavailable:
                entry["unavailable"] = self.w.unavailable[codec.name]
            topics[codec.name] = entry
        return topics
