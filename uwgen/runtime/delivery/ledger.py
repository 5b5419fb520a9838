"""Per-topic accounting that adds up, from what the bridge, its subscriptions and its link count.

Where a message can go, on the side that publishes the topic:

    published  = taken + dropped_by_subscription
    taken      = sent + sum(dropped_by_policy) + queued

- published: what the local publishers published, as far as the bridge's subscription can know
  (what it took plus what DDS reported lost to it; KEEP_LAST history overwrites are not reported
  by DDS, which is why `subscription_qos` sizes the history of fifo topics to hold what the link
  queue could);
- dropped_by_policy, by reason: the link scheduler's drops (superseded, overflow, expired,
  too_large, invalid) plus the bridge's own (encode_error, echo_guard, and superseded for the
  older messages of a latest-only topic taken in one poll: uwgen.bridge.polling);
- sent: handed to the link (whole, or all its fragments).

On the side that receives it:

    received   = delivered + sum(dropped_on_receive)

with `lost_on_link` the messages the receiver knows were lost on the way: fragmented messages
that never completed and whose first fragment said whose they were. Across the two sides
(`across()`, e.g. in the demo report): sent = received + lost, where lost is what did not
arrive, of which lost_on_link is the part the receiver saw.

`imbalances()` lists the identities that do not hold (empty when the books balance); tests and
the demo report use it.
"""
from __future__ import annotations

from typing import Any, Callable

from uwgen.runtime.link.scheduler import DROP_REASONS


class SubscriptionLosses:
    """Messages DDS reported lost to the bridge's local subscriptions (message-lost events),
    and publishers they could not match (incompatible-QoS events: their messages never
    reach the bridge, so they are in no count but this one)."""

    def __init__(self, warn: Callable[[str], None] | None = None) -> None:
        self.lost: dict[int, int] = {}
        self.incompatible: dict[int, int] = {}
        self.unsupported: set[int] = set()
        self.warn = warn

    def callbacks(self, ident: int, topic: str = "") -> Any:
        """`event_callbacks` for create_subscription of topic `ident` (None without rclpy)."""
        try:
            from rclpy.event_handler import SubscriptionEventCallbacks
        except ImportError:  # pragma: no cover - rclpy is there wherever a bridge runs
            return None

        def on_lost(info: Any) -> None:
            self.lost[ident] = self.lost.get(ident, 0) + int(info.total_count_change)

        def on_incompatible(info: Any) -> None:
            self.incompatible[ident] = self.incompatible.get(ident, 0) + int(info.total_count_change)
            if self.warn is not None:
                self.warn(f"{topic}: a publisher offers QoS incompatible with the bridge's "
                          f"subscription (policy {info.last_policy_kind}); its messages are not bridged")
        return SubscriptionEventCallbacks(message_lost=on_lost, incompatible_qos=on_incompatible)


def subscription_qos(codec: Any) -> Any:
    """The QoS of the bridge's local subscription: a fifo topic's history holds at least what the
    link queue can (`depth`), so the subscription never drops what the bridge would keep."""
    qos = codec.qos
    policy = getattr(codec, "policy", None)
    if policy is not None and policy.queue == "fifo" and policy.depth > qos.depth:
        return type(qos)(reliability=qos.reliability, durability=qos.durability, depth=policy.depth)
    return qos


def outgoing(counters: Any, channel: dict, subscription_lost: int, echo_dropped: int) -> dict:
    policy = {reason: int(channel.get(reason, 0)) for reason in DROP_REASONS}
    policy["superseded"] += getattr(counters, "superseded", 0)    # by the bridge, in one poll
    policy["encode_error"] = counters.encode_errors
    policy["echo_guard"] = echo_dropped
    return {
        "published": counters.taken + subscription_lost,
        "taken": counters.taken,
        "dropped_by_subscription": subscription_lost,
        "dropped_by_policy": policy,
        "queued": int(channel.get("queued", 0)),
        "sent": int(channel.get("sent", 0)),
    }


def incoming(counters: Any, lost_on_link: int) -> dict:
    return {
        "received": counters.received,
        "lost_on_link": lost_on_link,
        "delivered": counters.published,
        "dropped_on_receive": {"decode_error": counters.decode_errors,
                               "publish_error": counters.publish_errors},
    }


def lost_on_link(link_stats: dict) -> dict[int, int]:
    """Messages the link's reassembler gave up, by topic/service id (JSON may have made the keys text)."""
    frag = link_stats.get("fragments") or {}
    return {int(k): int(v) for k, v in (frag.get("lost_by_id") or {}).items()}


def imbalances(acc: dict) -> list[str]:
    """The identities of one side's accounting that do not hold."""
    bad = []
    if "taken" in acc:
        if acc["published"] != acc["taken"] + acc["dropped_by_subscription"]:
            bad.append(f"published {acc['published']} != taken {acc['taken']} + dropped by "
                       f"subscription {acc['dropped_by_subscription']}")
        dropped = sum(acc["dropped_by_policy"].values())
        if acc["taken"] != acc["sent"] + dropped + acc["queued"]:
            bad.append(f"taken {acc['taken']} != sent {acc['sent']} + dropped by policy {dropped} "
                       f"+ queued {acc['queued']}")
    if "received" in acc:
        dropped = sum(acc["dropped_on_receive"].values())
        if acc["received"] != acc["delivered"] + dropped:
            bad.append(f"received {acc['received']} != delivered {acc['delivered']} + dropped on "
                       f"receive {dropped}")
    return bad


def across(sender: dict, receiver: dict) -> dict:
    """One topic end to end: sent = received + lost (lost_on_link: the part the receiver saw)."""
    lost = sender["sent"] - receiver["received"]
    return {"sent": sender["sent"], "received": receiver["received"], "lost": lost,
            "lost_on_link": receiver["lost_on_link"], "unseen_loss": lost - receiver["lost_on_link"]}
