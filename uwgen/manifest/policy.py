"""Link policies (rate, queue, depth, ttl, priority, repair, strict, cut) and ROS QoS of manifest
entries, each key falling back to `defaults:` and then to the model's defaults."""
from __future__ import annotations

import yaml

from uwgen.manifest.model import DURABILITY, FIFO_DEFAULT_DEPTH, QUEUE_KINDS, RELIABILITY, LinkPolicy, Qos
from uwgen.manifest.nodes import Reader

POLICY_KEYS = ("rate", "queue", "depth", "ttl", "priority", "repair", "strict", "cut")
QOS_KEYS = ("reliability", "durability", "depth")
MAX_REPAIR = 32            # repair fragments per message (wire format section 11)


def read_policy(r: Reader, entries: dict, defaults: dict, base: LinkPolicy, label: str,
                is_defaults: bool = False, repair_nodes: dict[str, yaml.Node] | None = None) -> LinkPolicy:
    """Link policy from `entries`, falling back to `defaults`, then to `base`. A nonzero
    `repair` records its node in `repair_nodes[label]` (checked once the manifest is whole)."""

    def pick(key: str):
        if key in entries:
            return entries[key][1], True
        if key in defaults:
            return defaults[key][1], False
        return None, False

    rate, ttl, priority, queue = base.rate, base.ttl, base.priority, base.queue
    repair, strict, cut = base.repair, base.strict, base.cut
    node, _ = pick("strict")
    if node is not None:
        strict = r.boolean(node, f"strict of {label}")
    node, _ = pick("cut")
    if node is not None:
        cut = r.boolean(node, f"cut of {label}")
    node, _ = pick("repair")
    if node is not None:
        repair = r.integer(node, f"repair of {label}", 0, MAX_REPAIR)
        if repair and repair_nodes is not None:
            repair_nodes.setdefault(label, node)
    node, _ = pick("rate")
    if node is not None:
        rate = r.optional_number(node, f"rate of {label}")
    node, _ = pick("ttl")
    if node is not None:
        ttl = r.optional_number(node, f"ttl of {label}")
    node, _ = pick("priority")
    if node is not None:
        priority = r.integer(node, f"priority of {label}")
    queue_node, _ = pick("queue")
    if queue_node is not None:
        queue = r.choice(queue_node, f"queue of {label}", QUEUE_KINDS)
    depth_node, own = pick("depth")
    if queue == "latest":
        # A depth written next to a latest queue is a mistake; a depth in `defaults`
        # without a queue there is meant for the fifo topics and ignored by the others.
        if depth_node is not None and own and not (is_defaults and queue_node is None):
            raise r.error(depth_node, f"depth of {label} only applies to queue: fifo (queue latest keeps just the newest message)")
        depth = 1
    else:
        depth = base.depth if base.queue == "fifo" else FIFO_DEFAULT_DEPTH
        if depth_node is not None:
            depth = r.integer(depth_node, f"depth of {label}", 1)
    return LinkPolicy(rate=rate, queue=queue, depth=depth, ttl=ttl, priority=priority, repair=repair,
                      strict=strict, cut=cut)


def read_qos(r: Reader, node: yaml.Node, base: Qos) -> Qos:
    fields = r.mapping(node, "qos", QOS_KEYS)
    reliability, durability, depth = base.reliability, base.durability, base.depth
    if "reliability" in fields:
        reliability = r.choice(fields["reliability"][1], "qos reliability", RELIABILITY)
    if "durability" in fields:
        durability = r.choice(fields["durability"][1], "qos durability", DURABILITY)
    if "depth" in fields:
        depth = r.integer(fields["depth"][1], "qos depth", 1)
    return Qos(reliability, durability, depth)
