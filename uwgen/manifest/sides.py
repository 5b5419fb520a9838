"""The manifest's `sides:` section: each side's DESERT endpoint, link and sender id."""
from __future__ import annotations

import ipaddress
import re
from typing import Any

import yaml

from uwgen.manifest.model import LinkConfig, Side
from uwgen.manifest.nodes import Reader
from uwgen.manifest.security import sender_id

SIDE_KEYS = ("host", "port", "link", "sender_id")
LINK_KEYS = ("max_read_length", "period")
DESERT_MAX_READ_LENGTH = 4096   # DESERT crashes above this; the floor depends on the network (uwgen.linkfloor)
SIDE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
HOSTNAME_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def read_sides(b: Any, node: yaml.Node) -> dict[str, Side]:
    """Every side under `sides:` (each side's mistakes collected by the builder `b`); records
    the declared names, the security nodes and sender ids on `b` for later checks."""
    r = b.r
    entries = r.open_mapping(node, "sides")
    if not entries:
        raise r.error(node, "sides must name at least one side, e.g. surface: {port: 4000}")
    b.declared = set(entries)
    sides: dict[str, Side] = {}
    endpoints: dict[tuple[str, int], str] = {}
    for name, (key_node, value_node) in entries.items():
        side = b.checked(None, read_side, b, name, key_node, value_node, endpoints)
        if side is not None:
            sides[name] = side
    return sides


def read_side(b: Any, name: str, key_node: yaml.Node, value_node: yaml.Node,
              endpoints: dict[tuple[str, int], str]) -> Side:
    r = b.r
    if not SIDE_NAME.fullmatch(name):
        raise r.error(key_node, f"side name '{name}' must be letters, digits and '_', starting with a letter")
    what = f"side '{name}'"
    fields = r.mapping(value_node, what, SIDE_KEYS)
    host = "127.0.0.1"
    if "host" in fields:
        host_node = fields["host"][1]
        host = r.string(host_node, f"host of {what}")
        if not valid_host(host):
            raise r.error(host_node, f"host '{host}' of {what} is neither an IP address nor a host name")
    port_node = r.require(fields, "port", value_node, what)
    port = r.integer(port_node, f"port of {what}", 1, 65535)
    if (host, port) in endpoints:
        raise r.error(port_node, f"{what} uses {host}:{port}, already used by side '{endpoints[host, port]}' (DESERT serves one client per port)")
    endpoints[host, port] = name
    link = LinkConfig()
    if "link" in fields:
        link = read_link(r, fields["link"][1], what)
    b.sec.side_nodes[name] = value_node
    if "sender_id" in fields:
        b.sec.sender_nodes[name] = fields["sender_id"][1]
        b.senders[name] = sender_id(r, fields["sender_id"][1], name)
    return Side(name, host, port, link, r.where(value_node))


def read_link(r: Reader, node: yaml.Node, what: str) -> LinkConfig:
    fields = r.mapping(node, f"link of {what}", LINK_KEYS)
    base = LinkConfig()
    max_read_length = base.max_read_length
    period = base.period
    if "max_read_length" in fields:
        max_read_length = r.integer(fields["max_read_length"][1], f"max_read_length of {what}", 1,
                                    DESERT_MAX_READ_LENGTH)
    if "period" in fields:
        period = r.number(fields["period"][1], f"period of {what}")
    return LinkConfig(max_read_length, period)


def valid_host(host: str) -> bool:
    """An IP address or a DNS host name (labels of letters, digits and inner '-')."""
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    if len(host) > 253 or not host:
        return False
    labels = host.rstrip(".").split(".")
    return all(HOSTNAME_LABEL.fullmatch(label) for label in labels) and not labels[-1].isdigit()
