"""The manifest's `fleet:` section: N vehicles carrying the same interfaces, expanded at load.

    sides:
      surface: {port: 4000, sender_id: 1}          # the sides that lead the fleet
    fleet:
      vehicles: 3                 # how many (named by `name`), or a list of side names
      name: auv{n}                # side name of vehicle n (n = 1..N); default vehicle{n}
      namespace: /auv{n}          # its ROS namespace ({n}, {name}); default /{name}
      port: 4001                  # vehicle n's DESERT port: port + n - 1 (host as a side's)
      link: {max_read_length: 64, period: 0.2}
      sender_id: 2                # vehicle n's sender id: sender_id + n - 1
      id_stride: 10               # vehicle n's ids: the template's id + (n - 1) * id_stride
      topics:   [{name: pose, id: 10, type: ..., publisher: fleet}, ...]
      services: [{name: set_pen, id: 12, type: ..., server: fleet}]
      actions:  [...]

Each template entry is an ordinary topic, service or action entry whose name is relative
to the vehicle's namespace and whose `publisher`/`server` is `fleet` (each vehicle
itself) or a side under `sides:`. Vehicle n gets its own copy: name under its namespace,
its own ids, and as peers the sides under `sides:` and itself, so a command is addressed
to one vehicle (the surface's bridge routes by id) and telemetry comes from each vehicle
under its namespace. Vehicles are sides of their own (in `n` order after the declared
sides: the turn order), so the MAC, `uwgen analyze` and `uwgen emulate -m` see them as any
side. Every expanded entry is read by the same readers as a top-level one: its errors are
located at the template's line, naming the vehicle's copy (`topic /auv2/pose`).

Refused with a located error: more sides than the 4-bit sender id can name (16), sender
ids or ports past their range, ids past 255 after expansion, an `id_stride` smaller than
the template's span of ids (two vehicles would share an id), names that collide.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import yaml

from uwgen.manifest.model import MAX_SENDER_ID, Fleet, LinkConfig, Side
from uwgen.manifest.rosnames import validate_ros_name
from uwgen.manifest.security import sender_id as read_sender_id
from uwgen.manifest.sides import SIDE_NAME, read_link, valid_host

FLEET_KEYS = ("vehicles", "name", "namespace", "host", "port", "link", "sender_id", "id_stride",
              "topics", "services", "actions")
TEMPLATE_KINDS = (("topics", "topic", "publisher"), ("services", "service", "server"),
                  ("actions", "action", "server"))
VEHICLE = "fleet"                   # in a template's publisher/server: each vehicle itself
DEFAULT_NAME = "vehicle{n}"
DEFAULT_NAMESPACE = "/{name}"
MAX_SIDES = MAX_SENDER_ID + 1       # the envelope's sender id has 4 bits: one per side
MAX_ID = 255
INT_TAG = "tag:yaml.org,2002:int"
STR_TAG = "tag:yaml.org,2002:str"


@dataclass
class FleetTemplate:
    """The read `fleet:` section: the expanded sides and the template entries to copy."""

    fleet: Fleet
    entries: dict[str, list[tuple[yaml.Node, int]]] = field(default_factory=dict)  # kind -> (node, id)

    def peers(self, vehicle: str) -> tuple[str, ...]:
        return (*self.fleet.leaders, vehicle)


def read_fleet(b: Any, node: yaml.Node, sides: dict[str, Side]) -> FleetTemplate:
    """Read `fleet:` with the manifest builder `b`; adds each vehicle to `sides` (and to the
    builder's declared names, sender ids and security nodes) and returns the templates."""
    r = b.r
    fields = r.mapping(node, "fleet", FLEET_KEYS)
    leaders = tuple(sides)
    if VEHICLE in sides:
        raise r.error(node, f"a side under `sides:` is named '{VEHICLE}', the word fleet templates "
                            "use for each vehicle of the fleet: rename that side")
    vehicles_node = r.require(fields, "vehicles", node, "fleet")
    names = _vehicle_names(r, fields, vehicles_node)
    if len(leaders) + len(names) > MAX_SIDES:
        raise r.error(vehicles_node, f"a fleet of {len(names)} vehicles with {len(leaders)} other "
                      f"side(s) is {len(leaders) + len(names)} sides; each side's packets carry a "
                      f"4-bit sender id, so a network has at most {MAX_SIDES} sides "
                      f"({MAX_SIDES - max(1, len(leaders))} vehicles here)")
    for v in names:
        if v in sides:
            where = fields["name"][1] if "name" in fields else vehicles_node
            raise r.error(where, f"vehicle side '{v}' is already a side under `sides:`")
    namespaces = _namespaces(r, fields, names)
    _sides(b, fields, node, names, sides)
    if "sender_id" in fields:
        id_node = fields["sender_id"][1]
        first = read_sender_id(r, id_node, names[0])
        last = first + len(names) - 1
        if last > MAX_SENDER_ID:
            raise r.error(id_node, f"fleet sender_id {first} gives vehicle {names[-1]} sender id {last}; "
                          f"sender ids are 0..{MAX_SENDER_ID} (4 bits): start at most at "
                          f"{MAX_SENDER_ID + 1 - len(names)} for {len(names)} vehicles")
        for n, v in enumerate(names):
            b.senders[v] = first + n
            b.sec.sender_nodes[v] = id_node
    for v in names:
        b.sec.side_nodes[v] = node
    if b.declared is not None:
        b.declared |= set(names)
    templates = {kind: _templates(b, fields, kind, ref, leaders) for kind, _label, ref in TEMPLATE_KINDS}
    stride = _stride(r, fields, templates, len(names))
    return FleetTemplate(Fleet(tuple(names), namespaces, leaders, stride), templates)


def vehicle_names(r: Any, node: yaml.Node) -> list[str]:
    """The vehicles' side names of a `fleet:` section, in turn order (for readers that need
    the sides only: `uwgen.manifest.mac.mac_of_file`)."""
    fields = r.mapping(node, "fleet", FLEET_KEYS)
    return _vehicle_names(r, fields, r.require(fields, "vehicles", node, "fleet"))


def expand(b: Any, tmpl: FleetTemplate, kind: str, read: Callable[..., Any], sides: dict[str, Side],
           *args: Any) -> list[Any]:
    """Every vehicle's copy of the `kind` templates, read with `read(node, peer sides, *args)`
    (the builder's topic, service or action reader). A template with errors is reported once
    (for the first vehicle) and not copied."""
    items = []
    fleet = tmpl.fleet
    ref = next(ref for k, _label, ref in TEMPLATE_KINDS if k == kind)
    for node, ident in tmpl.entries.get(kind, []):
        for n, vehicle in enumerate(fleet.vehicles):
            copy = _copy(node, fleet.namespaces[vehicle], ident + n * fleet.id_stride, ref, vehicle)
            peers = tmpl.peers(vehicle)
            item = b.entry(read, copy, {p: sides[p] for p in peers if p in sides}, *args)
            if item is None:
                break
            items.append(replace(item, peers=peers))
    return items


def _vehicle_names(r: Any, fields: dict, node: yaml.Node) -> list[str]:
    if isinstance(node, yaml.SequenceNode):
        if "name" in fields:
            raise r.error(fields["name"][0], "fleet `name` names vehicles by number; with a list of "
                                             "vehicles, remove it")
        names = []
        for item in node.value:
            name = r.string(item, "a vehicle of the fleet")
            if not SIDE_NAME.fullmatch(name):
                raise r.error(item, f"vehicle name '{name}' must be letters, digits and '_', "
                                    "starting with a letter")
            if name in names:
                raise r.error(item, f"vehicle '{name}' is listed twice")
            names.append(name)
        if not names:
            raise r.error(node, "fleet vehicles must name at least one vehicle")
        return names
    count = r.integer(node, "fleet vehicles (a count, or a list of names)", 1, MAX_SIDES - 1)
    pattern, pattern_node = DEFAULT_NAME, node
    if "name" in fields:
        pattern_node = fields["name"][1]
        pattern = r.string(pattern_node, "fleet name")
    if count > 1 and "{n}" not in pattern:
        raise r.error(pattern_node, f"fleet name '{pattern}' must contain {{n}} (the vehicle's number) "
                                    f"so that the {count} vehicles get names of their own")
    names = [pattern.replace("{n}", str(n)) for n in range(1, count + 1)]
    for name in names:
        if not SIDE_NAME.fullmatch(name):
            raise r.error(pattern_node, f"fleet name '{pattern}' gives '{name}': side names must be "
                                        "letters, digits and '_', starting with a letter")
    return names


def _namespaces(r: Any, fields: dict, names: list[str]) -> dict[str, str]:
    pattern, node = DEFAULT_NAMESPACE, None
    if "namespace" in fields:
        node = fields["namespace"][1]
        pattern = r.string(node, "fleet namespace")
    out: dict[str, str] = {}
    for n, name in enumerate(names, 1):
        ns = pattern.replace("{n}", str(n)).replace("{name}", name)
        problem = validate_ros_name(ns)
        if problem:
            raise r.error(node or fields.get("vehicles", (None, None))[1],
                          f"fleet namespace '{pattern}' gives an invalid namespace for {name}: {problem}")
        if ns in out.values():
            raise r.error(node, f"fleet namespace '{pattern}' gives every vehicle the namespace {ns}: "
                                "use {n} or {name} in it")
        out[name] = ns
    return out


def _sides(b: Any, fields: dict, node: yaml.Node, names: list[str], sides: dict[str, Side]) -> None:
    r = b.r
    host = "127.0.0.1"
    if "host" in fields:
        host = r.string(fields["host"][1], "host of the fleet")
        if not valid_host(host):
            raise r.error(fields["host"][1], f"host '{host}' of the fleet is neither an IP address "
                                             "nor a host name")
    port_node = r.require(fields, "port", node, "fleet")
    first = r.integer(port_node, "port of the fleet (vehicle 1's; vehicle n's is port + n - 1)", 1, 65535)
    if first + len(names) - 1 > 65535:
        raise r.error(port_node, f"fleet port {first} gives vehicle {names[-1]} port "
                                 f"{first + len(names) - 1}, past 65535")
    link = read_link(r, fields["link"][1], "the fleet") if "link" in fields else LinkConfig()
    used = {(s.host, s.port): s.name for s in sides.values()}
    where = r.where(node)
    for n, name in enumerate(names):
        port = first + n
        if (host, port) in used:
            raise r.error(port_node, f"fleet port {first} gives vehicle {name} {host}:{port}, already "
                                     f"used by side '{used[host, port]}' (DESERT serves one client per port)")
        sides[name] = Side(name, host, port, link, where)


def _templates(b: Any, fields: dict, kind: str, ref: str, leaders: tuple[str, ...]) -> list[tuple[yaml.Node, int]]:
    """The template entries of `kind`, checked for what the copies cannot check: a relative
    name, an id, a publisher/server that is `vehicle` or a leading side."""
    if kind not in fields:
        return []
    r = b.r
    out = []
    label_kind = kind[:-1]
    for node in b.checked([], r.sequence, fields[kind][1], f"fleet {kind}"):
        with b.attempt():
            entries = r.open_mapping(node, f"a fleet {label_kind}")
            name_node = r.require(entries, "name", node, f"a fleet {label_kind}")
            name = r.string(name_node, f"fleet {label_kind} name")
            if name.startswith("/"):
                raise r.error(name_node, f"fleet {label_kind} name '{name}' must be relative: each "
                                         f"vehicle's copy is put under its namespace (e.g. 'pose' "
                                         "becomes /auv1/pose)")
            label = f"fleet {label_kind} {name}"
            ident = r.integer(r.require(entries, "id", node, label), f"id of {label}", 1, MAX_ID)
            side_node = r.require(entries, ref, node, label)
            side = r.string(side_node, f"{ref} of {label}")
            if side != VEHICLE and side not in leaders:
                raise r.error(side_node, f"{ref} '{side}' of {label} must be '{VEHICLE}' (each vehicle) "
                                         f"or a side under `sides:`")
            out.append((node, ident))
    return out


def _stride(r: Any, fields: dict, templates: dict, count: int) -> int:
    ids = [(ident, node) for nodes in templates.values() for node, ident in nodes]
    span = (max(i for i, _ in ids) - min(i for i, _ in ids) + 1) if ids else 1
    stride = span
    if "id_stride" in fields:
        node = fields["id_stride"][1]
        stride = r.integer(node, "fleet id_stride", 1, MAX_ID)
        if stride < span:
            low, high = min(i for i, _ in ids), max(i for i, _ in ids)
            raise r.error(node, f"fleet id_stride {stride} is smaller than the span of the template's "
                                f"ids ({low}..{high}: {span}); vehicles would share ids")
    for ident, node in ids:
        last = ident + (count - 1) * stride
        if last > MAX_ID:
            id_node = next(v for k, v in node.value if getattr(k, "value", None) == "id")
            raise r.error(id_node, f"id {ident} of this fleet entry is {last} for vehicle {count} "
                                   f"(id_stride {stride}); ids are 1..{MAX_ID}: fewer vehicles, a "
                                   "smaller id_stride or lower ids")
    return stride


def _copy(node: yaml.MappingNode, namespace: str, ident: int, ref: str, vehicle: str) -> yaml.MappingNode:
    """A template entry for one vehicle: name under its namespace, its id, `vehicle` as its
    side; every node keeps the template's marks, so errors point at the template."""
    value = []
    for key, val in node.value:
        k = getattr(key, "value", None)
        if k == "name":
            val = yaml.ScalarNode(STR_TAG, f"{namespace}/{val.value}", val.start_mark, val.end_mark)
        elif k == "id":
            val = yaml.ScalarNode(INT_TAG, str(ident), val.start_mark, val.end_mark)
        elif k == ref and getattr(val, "value", None) == VEHICLE:
            val = yaml.ScalarNode(STR_TAG, vehicle, val.start_mark, val.end_mark)
        value.append((key, val))
    return yaml.MappingNode(node.tag, value, node.start_mark, node.end_mark, node.flow_style)
