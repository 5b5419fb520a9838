"""Load and validate a network manifest (`uwgen.yaml`) into `uwgen.manifest.model` objects.

Every key is documented in `msg_samples/manifest-reference.yaml`. Every problem is a
`ManifestError` at the manifest's `file:line:column`; a broken interface definition that
the manifest names surfaces as the parser's own `DefinitionError` (located in the
`.msg`/`.srv` file, which is where the fix belongs).
"""
from __future__ import annotations

import dataclasses
import difflib
import ipaddress
import keyword
import re
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import yaml

from uwgen.idl import names as idl_names
from uwgen.idl.loader import InterfaceLibrary
from uwgen.errors import Collector, ErrorList
from uwgen.idl.model import DefinitionError, MessageDef, ServiceDef, SourceRef
from uwgen.manifest.model import (
    DURABILITY,
    FIFO_DEFAULT_DEPTH,
    NATIVE,
    PROFILES,
    QUEUE_KINDS,
    RELIABILITY,
    RMW_DESERT,
    RMW_DISCOVERY_ID,
    RMW_DISCOVERY_REQUEST_ID,
    SCHEMA_PERIOD_DEFAULT,
    Action,
    LinkConfig,
    LinkPolicy,
    Manifest,
    Qos,
    Security,
    Service,
    Side,
    Topic,
)
from uwgen.manifest.actions import ACTION_KEYS, FEEDBACK_KEYS, read_action  # noqa: F401 (keys re-exported)
from uwgen.manifest.fields import FieldsReader
from uwgen.manifest.nodes import ManifestError, Reader, compose
from uwgen.manifest.security import SecurityCheck, network_security, sender_id

__all__ = ["ManifestError", "load_manifest", "find_manifest", "MANIFEST_NAME", "FIFO_DEFAULT_DEPTH"]

MANIFEST_NAME = "uwgen.yaml"
ID_RANGE = (1, 255)

TOP_KEYS = ("network", "package", "profile", "sides", "fragment_id", "schema_id", "schema_period",
            "defaults", "topics", "services", "actions", "security")
SIDE_KEYS = ("host", "port", "link", "sender_id")
LINK_KEYS = ("max_read_length", "period")
POLICY_KEYS = ("rate", "queue", "depth", "ttl", "priority", "repair", "strict")
MAX_REPAIR = 32            # repair fragments per message (wire format section 11)
QOS_KEYS = ("reliability", "durability", "depth")
DEFAULTS_KEYS = (*POLICY_KEYS, "qos")
TOPIC_KEYS = ("name", "id", "type", "publisher", *POLICY_KEYS, "qos", "profile", "fields", "security",
              "reliability")
LINK_RELIABILITY = ("best_effort", "reliable")
SERVICE_KEYS = ("name", "id", "type", "server", "timeout", *POLICY_KEYS, "profile",
                "request_fields", "response_fields", "security")


NETWORK_NAME = re.compile(r"[a-z][a-z0-9_]*")
SIDE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
PYTHON_PACKAGE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
HOSTNAME_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")
ROS_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class _Reported(Exception):
    """An entry whose errors are already in the builder's collector: skip building it."""


class ManifestErrors(ManifestError, ErrorList):
    """Several problems in one manifest (each in `errors`, located); str() has one per line."""

    def __init__(self, errors: list[Exception], more: int = 0):
        ErrorList.__init__(self, errors, more)
        self.where = getattr(errors[0], "where", None)
        self.message = str(self)


def find_manifest(folder: Path) -> Path | None:
    """`<folder>/uwgen.yaml` if it exists (the convention), else None."""
    candidate = Path(folder) / MANIFEST_NAME
    return candidate if candidate.is_file() else None


def load_manifest(path: Path, lib: InterfaceLibrary) -> Manifest:
    """Read, validate and resolve the manifest at `path` against the interface library."""
    path = Path(path)
    root = compose(path)
    return _ManifestBuilder(Reader(path), lib).build(root)


def load_sides(path: Path) -> tuple[str, dict[str, Side]]:
    """The network name and the sides of the manifest at `path`, checked as load_manifest
    checks them (file:line:column errors), without resolving any type: for tools that need
    only the DESERT endpoints (`uwgen emulate -m`)."""
    path = Path(path)
    root = compose(path)
    builder = _ManifestBuilder(Reader(path), None)  # type: ignore[arg-type] - no types read
    r = builder.r
    if root is None:
        raise ManifestError(SourceRef(r.path, 1, 1), "empty manifest: expected a mapping with at least 'network' and 'sides'")
    top = r.mapping(root, "the manifest", TOP_KEYS)
    network = r.string(r.require(top, "network", root, "the manifest"), "network")
    sides = builder.sides(r.require(top, "sides", root, "the manifest"))
    builder.errors.raise_if_any(ManifestErrors)   # every broken side, each located
    return network, sides


def validate_ros_name(name: str) -> str | None:
    """Why `name` is not a fully qualified ROS 2 topic/service name, or None if it is one.

    The rules of rcl/rmw's full-name validation: leads with '/', tokens of letters, digits
    and '_' that do not start with a digit, no '//', no trailing '/'. Relative names are
    refused because a bridge node's namespace would silently change them.
    """
    if not name:
        return "a ROS name must not be empty"
    if not name.startswith("/"):
        return f"'{name}' is not a fully qualified ROS name: it must start with '/'"
    if name == "/":
        return "'/' alone is not a topic or service name"
    if name.endswith("/"):
        return f"'{name}' must not end with '/'"
    if "//" in name:
        return f"'{name}' must not contain '//'"
    for token in name[1:].split("/"):
        if token[0].isdigit():
            return f"'{name}': the part '{token}' must not start with a digit"
        if not ROS_TOKEN.fullmatch(token):   # the pattern is ASCII-only
            return f"'{name}' may contain only letters, digits, '_' and '/'"
    if len(name) > 255:
        return f"'{name[:20]}...' is longer than 255 characters"
    return None


def _valid_host(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    if len(host) > 253 or not host:
        return False
    labels = host.rstrip(".").split(".")
    return all(HOSTNAME_LABEL.fullmatch(label) for label in labels) and not labels[-1].isdigit()


@dataclass
class _IdUse:
    """Who holds an id, for duplicate and reservation messages."""

    what: str
    node: yaml.Node


class _ManifestBuilder:
    def __init__(self, reader: Reader, lib: InterfaceLibrary):
        self.r = reader
        self.lib = lib
        self.ids: dict[int, _IdUse] = {}
        self.repair_nodes: dict[str, yaml.Node] = {}    # "topic /x" -> its repair: value node
        self.sec = SecurityCheck(reader)
        self.senders: dict[str, int] = {}
        # Every independent mistake is reported in one pass (not one per run): each check
        # that can go wrong on its own runs under `attempt`/`checked` and lands here.
        self.errors = Collector()
        self.declared: set[str] | None = None   # side names written (None: sides unreadable)

    @contextmanager
    def attempt(self):
        with self.errors.attempt(ManifestError, DefinitionError):
            yield

    def checked(self, fallback, check, *args):
        """check(*args), or `fallback` when it fails (its error collected)."""
        with self.attempt():
            return check(*args)
        return fallback

    def entry(self, read, *args):
        """One topic, service or action: the entry, or None when it had errors (collected)."""
        start = self.errors.count
        try:
            with self.attempt():
                item = read(*args)
                if self.errors.count > start:
                    raise _Reported
                return item
        except _Reported:
            pass
        return None

    # -- top level -------------------------------------------------------------------

    def build(self, root: yaml.Node | None) -> Manifest:
        r = self.r
        if root is None:
            raise ManifestError(SourceRef(r.path, 1, 1), "empty manifest: expected a mapping with at least 'network' and 'sides'")
        top = r.mapping(root, "the manifest", TOP_KEYS)
        errors = self.errors

        network = self.checked("network", self.network, top, root)
        package = f"uwgen_{network}"
        if "package" in top:
            package = self.checked(package, self.package, top["package"][1])

        profile = NATIVE
        if "profile" in top:
            profile = self.checked(NATIVE, r.choice, top["profile"][1], "profile", PROFILES)

        security = Security()
        if "security" in top:
            self.sec.block = top["security"][1]
            security = self.checked(security, network_security, r, self.sec.block)
            if isinstance(self.sec.block, yaml.MappingNode):
                self.sec.mode_node = next((v for k, v in self.sec.block.value if k.value == "mode"),
                                          self.sec.block)

        sides = self.checked({}, self.sides, r.require(top, "sides", root, "the manifest"))

        # Policy keys from `defaults` stay nodes (merged per key into each topic, errors
        # located); validated here even if no topic uses them. Their qos is read once.
        defaults: dict = {}
        default_qos = Qos()
        if "defaults" in top:
            defaults = self.checked({}, r.mapping, top["defaults"][1], "defaults", DEFAULTS_KEYS)
            self.checked(None, self.policy, defaults, {}, LinkPolicy(), "defaults", True)
            if "qos" in defaults:
                default_qos = self.checked(default_qos, self.qos, defaults["qos"][1], default_qos)

        # Each entry is checked on its own, and within it each key that can be: every
        # mistake is reported, not just the first.
        topics, services, actions = [], [], []
        for key, items, read, args in (
                ("topics", topics, self.topic, (sides, defaults, default_qos, profile, security.mode)),
                ("services", services, self.service, (sides, profile, security.mode)),
                ("actions", actions, self.action, (sides, security.mode))):
            if key in top:
                for node in self.checked([], r.sequence, top[key][1], key):
                    item = self.entry(read, node, *args)
                    if item is not None:
                        items.append(item)
        for entries, kind in ((topics, "topic"), (services, "service"), (actions, "action")):
            with errors.attempt(ManifestError):
                self.unique_names(entries, kind)

        fragment_id = None
        if "fragment_id" in top:
            with errors.attempt(ManifestError):
                fragment_id = self.fragment_id(top["fragment_id"][1])
        schema_id = None
        if "schema_id" in top:
            with errors.attempt(ManifestError):
                schema_id = self.schema_id(top["schema_id"][1], fragment_id)
        schema_period = SCHEMA_PERIOD_DEFAULT
        if "schema_period" in top:
            node = top["schema_period"][1]
            none = isinstance(node, yaml.ScalarNode) and r.value(node) is None
            with errors.attempt(ManifestError):
                schema_period = None if none else r.number(node, "schema_period (seconds; null for none)")
        errors.raise_if_any(ManifestErrors)

        manifest = Manifest(
            network=network,
            source=r.path,
            profile=profile,
            package=package,
            sides=sides,
            topics=topics,
            services=services,
            actions=actions,
            fragment_id=fragment_id,
            schema_id=schema_id,
            schema_period=schema_period,
            security=security,
        )
        manifest = self.sec.finish(manifest, root, self.senders)
        if manifest.uses_rmw_desert():
            self.check_rmw_reserved(manifest, top)
        self.check_repair(manifest)
        return manifest

    def network(self, top: dict, root: yaml.Node) -> str:
        r = self.r
        network_node = r.require(top, "network", root, "the manifest")
        network = r.string(network_node, "network")
        if not NETWORK_NAME.fullmatch(network):
            raise r.error(network_node, f"network '{network}' must be lower case letters, digits and '_', starting with a letter")
        return network

    def package(self, node: yaml.Node) -> str:
        package = self.r.string(node, "package")
        if not PYTHON_PACKAGE.fullmatch(package) or keyword.iskeyword(package):
            raise self.r.error(node, f"package '{package}' must be a valid Python package name")
        return package

    # -- sides -----------------------------------------------------------------------

    def sides(self, node: yaml.Node) -> dict[str, Side]:
        r = self.r
        entries = r.open_mapping(node, "sides")
        if not entries:
            raise r.error(node, "sides must name at least one side, e.g. surface: {port: 4000}")
        self.declared = set(entries)
        sides: dict[str, Side] = {}
        endpoints: dict[tuple[str, int], str] = {}
        for name, (key_node, value_node) in entries.items():
            side = self.checked(None, self.side, name, key_node, value_node, endpoints)
            if side is not None:
                sides[name] = side
        return sides

    def side(self, name: str, key_node: yaml.Node, value_node: yaml.Node,
             endpoints: dict[tuple[str, int], str]) -> Side:
        r = self.r
        if not SIDE_NAME.fullmatch(name):
            raise r.error(key_node, f"side name '{name}' must be letters, digits and '_', starting with a letter")
        what = f"side '{name}'"
        fields = r.mapping(value_node, what, SIDE_KEYS)
        host = "127.0.0.1"
        if "host" in fields:
            host_node = fields["host"][1]
            host = r.string(host_node, f"host of {what}")
            if not _valid_host(host):
                raise r.error(host_node, f"host '{host}' of {what} is neither an IP address nor a host name")
        port_node = r.require(fields, "port", value_node, what)
        port = r.integer(port_node, f"port of {what}", 1, 65535)
        if (host, port) in endpoints:
            raise r.error(port_node, f"{what} uses {host}:{port}, already used by side '{endpoints[host, port]}' (DESERT serves one client per port)")
        endpoints[host, port] = name
        link = LinkConfig()
        if "link" in fields:
            link = self.link(fields["link"][1], what)
        self.sec.side_nodes[name] = value_node
        if "sender_id" in fields:
            self.sec.sender_nodes[name] = fields["sender_id"][1]
            self.senders[name] = sender_id(r, fields["sender_id"][1], name)
        return Side(name, host, port, link, r.where(value_node))

    def link(self, node: yaml.Node, what: str) -> LinkConfig:
        r = self.r
        fields = r.mapping(node, f"link of {what}", LINK_KEYS)
        base = LinkConfig()
        max_read_length = base.max_read_length
        period = base.period
        if "max_read_length" in fields:
            max_read_length = r.integer(fields["max_read_length"][1], f"max_read_length of {what}", 1, 4096)
        if "period" in fields:
            period = r.number(fields["period"][1], f"period of {what}")
        return LinkConfig(max_read_length, period)

    # -- topics and services ---------------------------------------------------------

    def common(self, node: yaml.Node, kind: str, keys: tuple[str, ...]) -> tuple[dict, str, int, str, str]:
        """Entries, name, id, type text and a label ('topic /x') shared by topics and services."""
        r = self.r
        entries = r.open_mapping(node, f"a {kind}")
        label = f"a {kind}"
        name_node = entries.get("name", (None, None))[1]
        if name_node is not None and isinstance(r.value(name_node), str):
            label = f"{kind} {r.value(name_node)}"   # names the entry in the unknown-key message
        r.check_keys(entries, label, keys)
        name_node = r.require(entries, "name", node, f"a {kind}")
        name = r.string(name_node, f"{kind} name")
        problem = validate_ros_name(name)
        if problem:
            raise r.error(name_node, f"invalid {kind} name: {problem}")
        label = f"{kind} {name}"
        id_node = r.require(entries, "id", node, label)
        ident = r.integer(id_node, f"id of {label}", *ID_RANGE)
        if ident in self.ids:
            first = self.ids[ident]
            raise r.error(id_node, f"id {ident} of {label} is already used by {first.what} (line {r.where(first.node).line}); ids are unique across topics, services and actions")
        self.ids[ident] = _IdUse(label, id_node)
        type_node = r.require(entries, "type", node, label)
        type_text = r.string(type_node, f"type of {label}")
        return entries, name, ident, type_text, label

    def resolve(self, type_node: yaml.Node, type_text: str, want: str, label: str):
        """The MessageDef (want='msg') or ServiceDef (want='srv') named by `type_text`."""
        r = self.r
        split = idl_names.split_type_name(type_text)
        if split is None:
            raise r.error(type_node, f"type '{type_text}' of {label} is not a type name: expected pkg/{want}/Name or pkg/Name")
        pkg, ns, name = split
        other = "srv" if want == "msg" else "msg"
        full = f"{pkg}/{want}/{name}"
        known = full in self.lib
        if (ns == other or (ns is None and not known)) and f"{pkg}/{other}/{name}" in self.lib:
            if want == "msg":
                raise r.error(type_node, f"type '{type_text}' is a service, but {label} needs a message type (pkg/msg/Name); declare it under services:")
            raise r.error(type_node, f"type '{type_text}' is a message, but {label} needs a service type (pkg/srv/Name); declare it under topics:")
        if ns == other:
            raise r.error(type_node, f"{label} needs a {'message' if want == 'msg' else 'service'} type pkg/{want}/Name, got '{type_text}'")
        if not known:
            raise r.error(type_node, f"unknown type '{type_text}' for {label}: {full} not found"
                                     f"{self.did_you_mean(full)} (looked in: {self.lib.looked_in()})")
        definition = self.lib.get(full)
        expected = MessageDef if want == "msg" else ServiceDef
        if not isinstance(definition, expected):  # a service's part, e.g. pkg/srv/Name_Request as a service
            raise r.error(type_node, f"type '{type_text}' of {label} is not a {want}")
        return full, definition

    def did_you_mean(self, full: str) -> str:
        """'; did you mean pkg/kind/Name?' for an unknown type: the same name in another
        package, else the closest spelling of its kind; '' when nothing is close."""
        pkg, kind, name = full.split("/")
        names = [n for n in self.lib.all_names() if n.split("/")[1] == kind]
        same = [n for n in names if n.split("/")[2].lower() == name.lower() and n != full]
        close = same or difflib.get_close_matches(full, names, n=1, cutoff=0.8)
        if not close:
            return ""
        return f"; did you mean {' or '.join(close[:2])}?"

    def side_ref(self, entries: dict, key: str, owner: yaml.Node, label: str, sides: dict[str, Side]) -> str:
        r = self.r
        node = r.require(entries, key, owner, label)
        side = r.string(node, f"{key} of {label}")
        if self.declared is not None and side not in self.declared:
            declared = ", ".join(sorted(self.declared))
            raise r.error(node, f"{key} '{side}' of {label} is not a declared side (sides: {declared})")
        return side

    def topic(self, node: yaml.Node, sides: dict[str, Side], defaults: dict, default_qos: Qos, profile: str,
              security: str = "off") -> Topic:
        r = self.r
        entries, name, ident, type_text, label = self.common(node, "topic", TOPIC_KEYS)
        type_name, definition = self.checked((None, None), self.resolve, entries["type"][1], type_text, "msg", label)
        publisher = self.checked(None, self.side_ref, entries, "publisher", node, label, sides)
        policy = self.checked(None, self.policy, entries, defaults, LinkPolicy(), label)
        qos = self.checked(None, self.qos, entries["qos"][1], default_qos) if "qos" in entries else default_qos
        topic_profile = self.checked(profile, r.choice, entries["profile"][1], f"profile of {label}", PROFILES) \
            if "profile" in entries else profile
        fields = self.checked((), self.fields, entries, "fields", definition, label, topic_profile) \
            if definition is not None else ()
        mode = self.checked("off", self.sec.entry_mode, entries, label, name, security)
        policy = self.checked(policy, self.reliability, entries, policy, topic_profile, label)
        return Topic(name, ident, type_name, definition, publisher, policy, qos, topic_profile, r.where(node), fields,
                     security=mode)

    def reliability(self, entries: dict, policy: LinkPolicy, profile: str, label: str) -> LinkPolicy:
        """`reliability:` of a topic on the link: best_effort (default) or reliable."""
        if "reliability" not in entries:
            return policy
        r = self.r
        node = entries["reliability"][1]
        if r.choice(node, f"reliability of {label}", LINK_RELIABILITY) != "reliable":
            return policy
        if profile == RMW_DESERT:
            raise r.error(node, f"reliability of {label}: profile rmw_desert cannot be reliable "
                                "(rmw_desert nodes read no acknowledgements and wire format 1 has "
                                "none); use profile native or packed, or best_effort")
        return dataclasses.replace(policy, reliable=True)

    def service(self, node: yaml.Node, sides: dict[str, Side], profile: str, security: str = "off") -> Service:
        r = self.r
        entries, name, ident, type_text, label = self.common(node, "service", SERVICE_KEYS)
        type_name, definition = self.checked((None, None), self.resolve, entries["type"][1], type_text, "srv", label)
        server = self.checked(None, self.side_ref, entries, "server", node, label, sides)
        timeout = Service.__dataclass_fields__["timeout"].default
        if "timeout" in entries:
            timeout = self.checked(timeout, r.number, entries["timeout"][1], f"timeout of {label}")
        base = Service.__dataclass_fields__["policy"].default_factory()
        policy = self.checked(None, self.policy, entries, {}, base, label)
        service_profile = self.checked(profile, r.choice, entries["profile"][1], f"profile of {label}", PROFILES) \
            if "profile" in entries else profile
        request_fields = response_fields = ()
        if definition is not None:
            request_fields = self.checked((), self.fields, entries, "request_fields", definition.request,
                                          f"the request of {label}", service_profile)
            response_fields = self.checked((), self.fields, entries, "response_fields", definition.response,
                                           f"the response of {label}", service_profile)
        mode = self.checked("off", self.sec.entry_mode, entries, label, name, security)
        return Service(name, ident, type_name, definition, server, timeout, policy, service_profile, r.where(node),
                       request_fields, response_fields, security=mode)

    def fields(self, entries: dict, key: str, msg: MessageDef, label: str, profile: str) -> tuple:
        """Field encodings under `key` (wire format section 8); never in profile rmw_desert."""
        if key not in entries:
            return ()
        key_node, node = entries[key]
        if profile == RMW_DESERT:
            raise self.r.error(key_node, f"{key} of {label}: profile rmw_desert cannot carry field encodings "
                                         "(an rmw_desert node could not read them); use profile native or packed")
        return FieldsReader(self.r, self.lib.get).read(node, msg, label)

    def action(self, node: yaml.Node, sides: dict[str, Side], security: str = "off") -> Action:
        return read_action(self, node, sides, security)   # uwgen.manifest.actions: the `actions:` section

    def policy(self, entries: dict, defaults: dict, base: LinkPolicy, label: str, is_defaults: bool = False) -> LinkPolicy:
        """Link policy from `entries`, falling back to `defaults`, then to `base`."""
        r = self.r

        def pick(key: str):
            if key in entries:
                return entries[key][1], True
            if key in defaults:
                return defaults[key][1], False
            return None, False

        rate, ttl, priority, queue = base.rate, base.ttl, base.priority, base.queue
        repair, strict = base.repair, base.strict
        node, _ = pick("strict")
        if node is not None:
            strict = r.boolean(node, f"strict of {label}")
        node, _ = pick("repair")
        if node is not None:
            repair = r.integer(node, f"repair of {label}", 0, MAX_REPAIR)
            if repair:
                self.repair_nodes.setdefault(label, node)
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
                          strict=strict)

    def qos(self, node: yaml.Node, base: Qos) -> Qos:
        r = self.r
        fields = r.mapping(node, "qos", QOS_KEYS)
        reliability, durability, depth = base.reliability, base.durability, base.depth
        if "reliability" in fields:
            reliability = r.choice(fields["reliability"][1], "qos reliability", RELIABILITY)
        if "durability" in fields:
            durability = r.choice(fields["durability"][1], "qos durability", DURABILITY)
        if "depth" in fields:
            depth = r.integer(fields["depth"][1], "qos depth", 1)
        return Qos(reliability, durability, depth)

    def unique_names(self, items: list, kind: str) -> None:
        seen: dict[str, object] = {}
        for item in items:
            if item.name in seen:
                first = seen[item.name]
                raise ManifestError(item.where, f"{kind} {item.name} is declared twice (first at line {first.where.line})")
            seen[item.name] = item

    def fragment_id(self, node: yaml.Node) -> int | None:
        r = self.r
        if isinstance(node, yaml.ScalarNode) and r.value(node) is None:
            return None
        ident = r.integer(node, "fragment_id", *ID_RANGE)
        if ident in self.ids:
            user = self.ids[ident]
            raise r.error(node, f"fragment_id {ident} collides with the id of {user.what} (line {r.where(user.node).line}); it must be an id no topic or service uses")
        return ident

    def check_repair(self, manifest: Manifest) -> None:
        """`repair` needs fragments: a fragment_id, and the native profile."""
        for entry in (*manifest.topics, *manifest.services):
            if not entry.policy.repair:
                continue
            kind = "topic" if entry in manifest.topics else "service"
            node = self.repair_nodes[f"{kind} {entry.name}"]
            if manifest.fragment_id is None:
                raise self.r.error(node, f"repair of {kind} {entry.name} needs fragments: set fragment_id "
                                   f"(repair fragments travel on it)")
            if entry.profile == RMW_DESERT:
                raise self.r.error(node, f"repair of {kind} {entry.name}: profile rmw_desert messages are "
                                   f"never fragmented (rmw_desert nodes cannot reassemble them); use "
                                   f"profile native or remove repair")

    def schema_id(self, node: yaml.Node, fragment_id: int | None) -> int | None:
        r = self.r
        if isinstance(node, yaml.ScalarNode) and r.value(node) is None:
            return None
        ident = r.integer(node, "schema_id", *ID_RANGE)
        if ident in self.ids:
            user = self.ids[ident]
            raise r.error(node, f"schema_id {ident} collides with the id of {user.what} (line {r.where(user.node).line}); it must be an id no topic or service uses")
        if ident == fragment_id:
            raise r.error(node, f"schema_id {ident} is also the fragment_id; the two reserved ids must differ")
        return ident

    def check_rmw_reserved(self, manifest: Manifest, top: dict) -> None:
        r = self.r
        user = next(t for t in (*manifest.topics, *manifest.services) if t.profile == RMW_DESERT)
        reason = f"while any topic or service uses profile rmw_desert ({user.name} at line {user.where.line} does)"
        reserved = {RMW_DISCOVERY_ID: "/discovery", RMW_DISCOVERY_REQUEST_ID: "/discovery_request"}
        for ident, topic in reserved.items():
            if ident in self.ids:
                use = self.ids[ident]
                raise r.error(use.node, f"id {ident} of {use.what} is reserved for rmw_desert's {topic} {reason}")
        if manifest.fragment_id in reserved:
            raise r.error(top["fragment_id"][1], f"fragment_id {manifest.fragment_id} is reserved for rmw_desert's {reserved[manifest.fragment_id]} {reason}")
        if manifest.schema_id in reserved:
            raise r.error(top["schema_id"][1], f"schema_id {manifest.schema_id} is reserved for rmw_desert's {reserved[manifest.schema_id]} {reason}")
