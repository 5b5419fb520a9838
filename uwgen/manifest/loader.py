"""Load and validate a network manifest (`uwgen.yaml`) into `uwgen.manifest.model` objects.

Every key is documented in `msg_samples/manifest-reference.yaml`. Every problem is a
`ManifestError` at the manifest's `file:line:column`; a broken interface definition that
the manifest names surfaces as the parser's own `DefinitionError` (located in the
`.msg`/`.srv` file, which is where the fix belongs).
"""
from __future__ import annotations

import dataclasses
import keyword
import re
from contextlib import contextmanager
from pathlib import Path

import yaml

from uwgen.errors import Collector, ErrorList
from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import DefinitionError, MessageDef, SourceRef
from uwgen.manifest import checks
from uwgen.manifest.actions import ACTION_KEYS, FEEDBACK_KEYS, read_action  # noqa: F401 (keys re-exported)
from uwgen.manifest.checks import ID_RANGE, IdUse
from uwgen.manifest.fields import FieldsReader
from uwgen.manifest.fleet import FleetTemplate, expand, read_fleet
from uwgen.manifest.model import (
    FIFO_DEFAULT_DEPTH,  # noqa: F401 (re-exported)
    NATIVE,
    PROFILES,
    RMW_DESERT,
    SCHEMA_PERIOD_DEFAULT,
    Action,
    LinkPolicy,
    Manifest,
    Qos,
    MacConfig,
    Security,
    Service,
    Side,
    Topic,
)
from uwgen.manifest.nodes import ManifestError, Reader, compose
from uwgen.manifest.rosnames import ROS_TOKEN, validate_ros_name  # noqa: F401 (re-exported)
from uwgen.manifest.policy import POLICY_KEYS, QOS_KEYS, read_policy, read_qos  # noqa: F401 (QOS_KEYS re-exported)
from uwgen.manifest.mac import check_turns_wire, read_mac
from uwgen.manifest.security import SecurityCheck, network_security
from uwgen.manifest.sides import LINK_KEYS, SIDE_KEYS, SIDE_NAME, read_sides  # noqa: F401 (re-exported)
from uwgen.manifest.typeref import resolve_type

__all__ = ["ManifestError", "load_manifest", "find_manifest", "MANIFEST_NAME", "FIFO_DEFAULT_DEPTH"]

MANIFEST_NAME = "uwgen.yaml"

TOP_KEYS = ("network", "package", "profile", "sides", "fleet", "fragment_id", "schema_id",
            "schema_period", "defaults", "topics", "services", "actions", "security", "mac")
DEFAULTS_KEYS = (*POLICY_KEYS, "qos")
TOPIC_KEYS = ("name", "id", "type", "publisher", *POLICY_KEYS, "qos", "profile", "fields", "security",
              "reliability")
LINK_RELIABILITY = ("best_effort", "reliable")
# `cut` is a topic's: a service's messages have a max age (its timeout), and those are never cut
SERVICE_KEYS = ("name", "id", "type", "server", "timeout",
                *(k for k in POLICY_KEYS if k != "cut"), "profile",
                "request_fields", "response_fields", "security")


NETWORK_NAME = re.compile(r"[a-z][a-z0-9_]*")
PYTHON_PACKAGE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


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
    try:
        return candidate if candidate.is_file() else None
    except OSError:         # a folder name too long to look into: it holds no manifest we can read
        return None


def load_manifest(path: Path, lib: InterfaceLibrary) -> Manifest:
    """Read, validate and resolve the manifest at `path` against the interface library."""
    path = Path(path)
    root = compose(path)
    return _ManifestBuilder(Reader(path), lib).build(root)


class _Errors(Collector):
    """The builder's collector: leaves out what only follows from a key already refused
    (a field spec that "says nothing" once its misspelled key is skipped)."""

    def __init__(self, reader: Reader):
        super().__init__()
        self.reader = reader

    def add(self, error: Exception) -> None:
        kept = [e for e in (getattr(error, "errors", None) or [error]) if not self.reader.consequence(e)]
        if kept:
            super().add(ManifestErrors(kept) if len(kept) > 1 else kept[0])
        elif not self.errors:
            super().add(error)      # never lose the only error there is


class _ManifestBuilder:
    def __init__(self, reader: Reader, lib: InterfaceLibrary):
        self.r = reader
        self.lib = lib
        self.ids: dict[int, IdUse] = {}
        self.repair_nodes: dict[str, yaml.Node] = {}    # "topic /x" -> its repair: value node
        self.sec = SecurityCheck(reader)
        self.senders: dict[str, int] = {}
        # Every independent mistake is reported in one pass (not one per run): each check
        # that can go wrong on its own runs under `attempt`/`checked` and lands here.
        self.errors = _Errors(reader)
        reader.collect = self.errors            # unknown and repeated keys too (Reader.mapping)
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
        security_read = True
        if "security" in top:
            self.sec.block = top["security"][1]
            before = errors.count
            security = self.checked(security, network_security, r, self.sec.block)
            security_read = errors.count == before
            if isinstance(self.sec.block, yaml.MappingNode):
                self.sec.mode_node = next((v for k, v in self.sec.block.value if k.value == "mode"),
                                          self.sec.block)
                self.sec.tag_node = next((v for k, v in self.sec.block.value
                                          if k.value == "tag_bytes"), self.sec.block)

        sides = self.checked({}, read_sides, self, r.require(top, "sides", root, "the manifest"))
        fleet: FleetTemplate | None = None
        if "fleet" in top:   # vehicles become sides; their entries are copied below
            fleet = self.checked(None, read_fleet, self, top["fleet"][1], sides)
        mac = MacConfig()
        if "mac" in top and sides:   # after the fleet: its vehicles have slots and turns too
            mac = self.checked(mac, read_mac, r, top["mac"][1], sides)

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
            if fleet is not None:
                items += expand(self, fleet, key, read, sides, *args[1:])
        for entries, kind in ((topics, "topic"), (services, "service"), (actions, "action")):
            with errors.attempt(ManifestError):
                checks.unique_names(entries, kind)

        fragment_id = None
        if "fragment_id" in top:
            with errors.attempt(ManifestError):
                fragment_id = checks.reserved_id(r, self.ids, top["fragment_id"][1], "fragment_id")
        schema_id = None
        if "schema_id" in top:
            with errors.attempt(ManifestError):
                schema_id = checks.schema_id(r, self.ids, top["schema_id"][1], fragment_id)
        schema_period = SCHEMA_PERIOD_DEFAULT
        if "schema_period" in top:
            node = top["schema_period"][1]
            none = isinstance(node, yaml.ScalarNode) and r.value(node) is None
            with errors.attempt(ManifestError):
                schema_period = None if none else r.number(node, "schema_period (seconds; null for none)")

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
            fleet=fleet.fleet if fleet is not None else None,
            mac=mac,
        )
        if "mac" in top:
            with errors.attempt(ManifestError):
                check_turns_wire(r, top["mac"][1], mac, manifest.uses_rmw_desert())
        # The checks of the whole manifest run on what could be read, also when some of it
        # could not (so its mistakes come in the same pass); the security set-up's only when
        # its block was read (else "no key named" would only echo that block's own error).
        if security_read and self.declared is not None:
            with errors.attempt(ManifestError):
                manifest = self.sec.finish(manifest, root, self.senders)
        if manifest.uses_rmw_desert():
            with errors.attempt(ManifestError):
                checks.check_rmw_reserved(r, self.ids, manifest, top)
            with errors.attempt(ManifestError):
                checks.check_mixed_commands(manifest)
        with errors.attempt(ManifestError):
            checks.check_repair(r, manifest, self.repair_nodes)
        errors.raise_if_any(ManifestErrors)
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
        self.ids[ident] = IdUse(label, id_node)
        type_node = r.require(entries, "type", node, label)
        type_text = r.string(type_node, f"type of {label}")
        return entries, name, ident, type_text, label

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
        type_name, definition = self.checked((None, None), resolve_type, r, self.lib, entries["type"][1], type_text, "msg", label)
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
        type_name, definition = self.checked((None, None), resolve_type, r, self.lib, entries["type"][1], type_text, "srv", label)
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

    def policy(self, entries: dict, defaults: dict, base: LinkPolicy, label: str,
               is_defaults: bool = False) -> LinkPolicy:
        return read_policy(self.r, entries, defaults, base, label, is_defaults, self.repair_nodes)

    def qos(self, node: yaml.Node, base: Qos) -> Qos:
        return read_qos(self.r, node, base)
