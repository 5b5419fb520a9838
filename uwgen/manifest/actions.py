"""The `actions:` section of a manifest (see msg_samples/manifest-reference.yaml).

Read by `uwgen.manifest.loader`'s builder, which owns ids, names, sides and link policy;
this module adds what only actions have: the action type, the two timeouts, max_goals and
the latest-only feedback policy. Errors are ManifestErrors at file:line:column.
"""
from __future__ import annotations

from typing import Any

import yaml

from uwgen.idl import names as idl_names
from uwgen.idl.model import ActionDef
from uwgen.manifest.model import (ACTION_HANDLES, MAX_GOALS_LIMIT, NATIVE, PROFILES, Action,
                                  LinkPolicy, Side)
from uwgen.manifest.typeref import did_you_mean

ACTION_KEYS = ("name", "id", "type", "server", "accept_timeout", "result_timeout", "max_goals",
               "rate", "queue", "depth", "ttl", "priority", "feedback", "profile", "security")
FEEDBACK_KEYS = ("rate", "ttl", "priority")


def read_action(b: Any, node: yaml.Node, sides: dict[str, Side], security: str = "off") -> Action:
    """One entry of `actions:`, read with the manifest builder `b` (ids, names, sides and
    link policy keys as for services; `security` is the network's default mode)."""
    r = b.r
    entries, name, ident, type_text, label = b.common(node, "action", ACTION_KEYS)
    type_name, definition = b.checked((None, None), resolve_action, b, entries["type"][1], type_text, label)
    server = b.checked(None, b.side_ref, entries, "server", node, label, sides)
    base = Action.__dataclass_fields__
    accept_timeout, result_timeout = base["accept_timeout"].default, base["result_timeout"].default
    if "accept_timeout" in entries:
        accept_timeout = r.number(entries["accept_timeout"][1], f"accept_timeout of {label}")
    if "result_timeout" in entries:
        result_timeout = r.number(entries["result_timeout"][1], f"result_timeout of {label}")
    max_goals = base["max_goals"].default
    # Every client side has its own share of the handles (model.handle_range), which must
    # hold more than max_goals.
    share = ACTION_HANDLES // max(1, len(sides) - 1)
    limit = min(MAX_GOALS_LIMIT, share - 1)
    if "max_goals" in entries:
        node_ = entries["max_goals"][1]
        max_goals = r.integer(node_, f"max_goals of {label}", 1, MAX_GOALS_LIMIT)
        if max_goals > limit:
            raise r.error(node_, f"max_goals of {label} must be at most {limit} with "
                                 f"{len(sides) - 1} client sides ({share} goal handles each)")
    elif max_goals > limit:
        if limit < 1:
            raise r.error(node, f"{label}: too many sides ({len(sides)}) for an action: each "
                                f"client side needs at least 2 of the {ACTION_HANDLES} goal handles")
        max_goals = limit
    policy = b.policy(entries, {}, base["policy"].default_factory(), label)
    feedback = base["feedback"].default_factory()
    if "feedback" in entries:
        feedback = read_feedback(b, entries["feedback"][1], feedback, label)
    if "profile" in entries:
        profile_node = entries["profile"][1]
        if r.choice(profile_node, f"profile of {label}", PROFILES) != NATIVE:
            raise r.error(profile_node, f"{label}: actions are carried in profile native only "
                                        "(rmw_desert nodes have no actions)")
    mode = b.sec.entry_mode(entries, label, name, security)
    return Action(name, ident, type_name, definition, server, accept_timeout, result_timeout,
                  max_goals, policy, feedback, NATIVE, r.where(node), security=mode)


def resolve_action(b: Any, type_node: yaml.Node, type_text: str, label: str) -> tuple[str, ActionDef]:
    """The ActionDef named by `type_text` (pkg/action/Name or pkg/Name)."""
    r = b.r
    split = idl_names.split_type_name(type_text)
    if split is None:
        raise r.error(type_node, f"type '{type_text}' of {label} is not a type name: expected pkg/action/Name or pkg/Name")
    pkg, ns, name = split
    full = f"{pkg}/action/{name}"
    if ns not in (None, "action") or full not in b.lib:
        for other, kind in (("msg", "a message"), ("srv", "a service")):
            if ns in (None, other) and f"{pkg}/{other}/{name}" in b.lib:
                raise r.error(type_node, f"type '{type_text}' is {kind}, but {label} needs an action type (pkg/action/Name)")
        raise r.error(type_node, f"unknown type '{type_text}' for {label}: {full} not found"
                                 f"{did_you_mean(b.lib, full)} (looked in: {b.lib.looked_in()})")
    definition = b.lib.get(full)
    if not isinstance(definition, ActionDef):  # an action's part, e.g. pkg/action/Name_Goal
        raise r.error(type_node, f"type '{type_text}' of {label} is not an action")
    return full, definition


def read_feedback(b: Any, node: yaml.Node, base: LinkPolicy, label: str) -> LinkPolicy | None:
    """`feedback: {rate, ttl, priority}` (always latest-only), or `feedback: false`."""
    r = b.r
    if isinstance(node, yaml.ScalarNode) and r.value(node) is False:
        return None
    what = f"feedback of {label}"
    if not isinstance(node, yaml.MappingNode):
        raise r.error(node, f"{what} must be a mapping (rate, ttl, priority) or false, got {r.describe(node)}")
    fields = r.mapping(node, what, FEEDBACK_KEYS)
    rate, ttl, priority = base.rate, base.ttl, base.priority
    if "rate" in fields:
        rate = r.number(fields["rate"][1], f"feedback rate of {label}")
    if "ttl" in fields:
        ttl = r.optional_number(fields["ttl"][1], f"feedback ttl of {label}")
    if "priority" in fields:
        priority = r.integer(fields["priority"][1], f"feedback priority of {label}")
    return LinkPolicy(rate=rate, queue="latest", depth=1, ttl=ttl, priority=priority)
