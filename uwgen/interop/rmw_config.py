"""rmw_desert's id table (`ros_allowed_topics.conf`) both ways.

rmw_desert reads `{"topics": {"/turtle1/cmd_vel": 4, ...}}` (services by their name,
`/discovery` at 1 and `/discovery_request` at 2) and never sends or receives a name
missing from it. Every device on one DESERT network must share the table, so uwgen

- writes it from a manifest (`export_conf`), deterministically: same manifest, same
  bytes, so it can be committed and diffed;
- starts a manifest from an existing one (`manifest_from_conf`): names and ids come from
  the table; the types, which the table does not have, from `--type` options, a hints
  file or built-in conventions, resolved against the interface library; the side of
  each entry from the caller. The result is YAML with comments, meant to be reviewed.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from uwgen import safefile, yamltext
from uwgen.idl import names as idl_names
from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import SourceRef
from uwgen.interop.beacons import (
    DISCOVERY_ID, DISCOVERY_REQUEST_ID, DISCOVERY_REQUEST_TOPIC, DISCOVERY_TOPIC, PROFILE)
from uwgen.interop.hints import KNOWN_TYPES
from uwgen.manifest.loader import validate_ros_name
from uwgen.manifest.model import Manifest

CONF_LIMIT = 1024 ** 2      # an rmw_desert configuration: a line per topic, never a megabyte
RESERVED = {DISCOVERY_TOPIC: DISCOVERY_ID, DISCOVERY_REQUEST_TOPIC: DISCOVERY_REQUEST_ID}


class RmwConfigError(Exception):
    """Bad input to an export or import; str() is `file:line:column: message` when located."""

    def __init__(self, message: str, where: SourceRef | str | None = None):
        self.where = where
        self.message = message
        super().__init__(f"{where}: {message}" if where else message)


# =========================================================================== export

@dataclass(frozen=True)
class ConfExport:
    text: str                       # the JSON file's content, newline-terminated
    table: dict[str, int]           # what it holds, in file order
    omitted: list[str] = field(default_factory=list)   # manifest names left out, and why


def conf_table(manifest: Manifest, include_native: bool = False) -> tuple[dict[str, int], list[str]]:
    """The id table of `manifest` (in id order) and the names left out with the reason.

    When any entry uses profile rmw_desert, the table gets `/discovery` and
    `/discovery_request` and, unless `include_native`, only the rmw_desert entries: an
    rmw_desert node listing a native-profile name would misread it (bools, doubles),
    while one not listing it ignores it. A manifest without the profile is written
    whole, without the discovery ids, as a plain id table.
    """
    rmw = manifest.uses_rmw_desert()
    entries: list[tuple[int, str]] = []
    omitted: list[str] = []
    for item in (*manifest.topics, *manifest.services):
        if rmw and item.profile != PROFILE and not include_native:
            omitted.append(f"{item.name} (id {item.id}): profile {item.profile}, which "
                           "rmw_desert nodes cannot decode (--include-native lists it)")
            continue
        entries.append((item.id, item.name))
    for action in getattr(manifest, "actions", ()):
        omitted.append(f"{action.name} (id {action.id}): an action (wire format 13), which "
                       "rmw_desert nodes do not carry")
    if rmw:
        entries += [(DISCOVERY_ID, DISCOVERY_TOPIC), (DISCOVERY_REQUEST_ID, DISCOVERY_REQUEST_TOPIC)]
    entries.sort()
    return {name: ident for ident, name in entries}, omitted


def export_conf(manifest: Manifest, include_native: bool = False) -> ConfExport:
    """rmw_desert's `ros_allowed_topics.conf` for `manifest` (see conf_table)."""
    table, omitted = conf_table(manifest, include_native)
    text = json.dumps({"topics": table}, indent=2, ensure_ascii=True) + "\n"
    return ConfExport(text, table, omitted)


# =========================================================================== read

def _locate(text: str, source: str, needle: str) -> SourceRef | str:
    """Where `needle` (a JSON-quoted key) first occurs in `text`, for error messages."""
    index = text.find(needle)
    if index < 0:
        return source
    line = text.count("\n", 0, index) + 1
    column = index - (text.rfind("\n", 0, index) + 1) + 1
    return SourceRef(Path(source), line, column)


def parse_conf(text: str, source: str = "<ros_allowed_topics.conf>") -> dict[str, int]:
    """The id table in rmw_desert's JSON, in file order; RmwConfigError when invalid.

    Checks what rmw_desert would get wrong silently: duplicate names or ids, ids outside
    1..255, names that are not fully qualified ROS names, and ids 1 and 2 on anything
    but `/discovery` and `/discovery_request`.
    """
    def no_duplicates(pairs):
        seen: dict = {}
        for key, value in pairs:
            if key in seen:
                raise RmwConfigError(f"name {key} appears twice",
                                     _locate(text, source, json.dumps(key)))
            seen[key] = value
        return seen

    try:
        data = json.loads(text, object_pairs_hook=no_duplicates)
    except json.JSONDecodeError as exc:
        raise RmwConfigError(f"not valid JSON: {exc.msg}",
                             SourceRef(Path(source), exc.lineno, exc.colno)) from None
    if not isinstance(data, dict) or not isinstance(data.get("topics"), dict):
        raise RmwConfigError('expected an object {"topics": {"/name": id, ...}}',
                             SourceRef(Path(source), 1, 1))
    table: dict[str, int] = {}
    by_id: dict[int, str] = {}
    for name, ident in data["topics"].items():
        where = _locate(text, source, json.dumps(name))
        if type(ident) is not int or not 1 <= ident <= 255:
            raise RmwConfigError(f"id of {name} must be an integer 1..255, got {json.dumps(ident)}",
                                 where)
        problem = validate_ros_name(name)
        if problem:
            raise RmwConfigError(f"invalid name: {problem}", where)
        if ident in by_id:
            raise RmwConfigError(f"id {ident} of {name} is already used by {by_id[ident]}", where)
        if name in RESERVED and ident != RESERVED[name]:
            raise RmwConfigError(f"{name} must have id {RESERVED[name]} (rmw_desert's discovery), "
                                 f"got {ident}", where)
        if ident in RESERVED.values() and name not in RESERVED:
            reserved = next(n for n, i in RESERVED.items() if i == ident)
            raise RmwConfigError(f"id {ident} of {name} is reserved for rmw_desert's {reserved}",
                                 where)
        table[name] = ident
        by_id[ident] = name
    return table


def read_conf(path: Path) -> dict[str, int]:
    path = Path(path)
    try:
        text = safefile.read_text(path, "rmw_desert configuration", CONF_LIMIT)
    except safefile.UnreadableFile as exc:
        if exc.line:
            raise RmwConfigError(exc.reason, SourceRef(path, exc.line, exc.column)) from None
        raise RmwConfigError(exc.message) from None
    return parse_conf(text, str(path))


# =========================================================================== types

@dataclass(frozen=True)
class ResolvedType:
    full_name: str      # pkg/msg/Name or pkg/srv/Name
    origin: str         # where it came from, for the manifest comment

    @property
    def is_service(self) -> bool:
        return "/srv/" in self.full_name


def resolve_type_text(text: str, lib: InterfaceLibrary) -> str:
    """The full name of `text`: `pkg/msg/Name`, `pkg/srv/Name`, `pkg/Name` or a bare `Name`.

    A bare name is looked up among every known interface and must be unambiguous.
    Raises ValueError saying what is wrong (unknown, ambiguous with the candidates).
    """
    text = text.strip()
    if "/" not in text:
        if not idl_names.is_message_name(text):
            raise ValueError(f"'{text}' is not a type name")
        candidates = [n for n in lib.all_names()
                      if n.endswith(f"/msg/{text}") or n.endswith(f"/srv/{text}")]
        if not candidates:
            raise ValueError(f"no known message or service is called {text}")
        if len(candidates) > 1:
            raise ValueError(f"{text} is ambiguous: {', '.join(candidates)}; give pkg/msg/{text}")
        return candidates[0]
    split = idl_names.split_type_name(text)
    if split is None:
        raise ValueError(f"'{text}' is not a type name (pkg/msg/Name, pkg/srv/Name, pkg/Name)")
    pkg, ns, name = split
    spaces = [ns] if ns else ["msg", "srv"]
    found = [f"{pkg}/{s}/{name}" for s in spaces if f"{pkg}/{s}/{name}" in lib]
    if not found:
        raise ValueError(f"{text} is not a known interface ({lib.describe_unknown(text)})")
    if len(found) > 1:
        raise ValueError(f"{text} is ambiguous: {', '.join(found)}")
    return found[0]


def resolve_types(names: list[str], lib: InterfaceLibrary, explicit: dict[str, str],
                  hints: dict[str, str] | None = None, builtin: bool = True
                  ) -> dict[str, ResolvedType]:
    """A type for every name, from `explicit`, then `hints`, then the built-in table.

    Raises RmwConfigError listing every name still without a type and every given type
    that does not resolve, so one run shows the whole fix.
    """
    hints = hints or {}
    resolved: dict[str, ResolvedType] = {}
    problems: list[str] = []
    for unknown in sorted(set(explicit) - set(names)):
        problems.append(f"--type {unknown}: no such name in the id table")
    for name in names:
        for origin, table in (("--type", explicit), ("hints file", hints)):
            if name in table:
                try:
                    resolved[name] = ResolvedType(resolve_type_text(table[name], lib), origin)
                except ValueError as exc:
                    problems.append(f"{name}: {origin} gives {table[name]!r}: {exc}")
                break
        else:
            known = KNOWN_TYPES.get(name) if builtin else None
            if known and known in lib:
                resolved[name] = ResolvedType(known, "by convention for this name: check it")
            elif known:
                problems.append(f"{name}: by convention {known}, which is not installed or "
                                "in the interface folders; give --type")
            else:
                problems.append(f"{name}: type unknown; give --type {name}=pkg/msg/Type")
    if problems:
        raise RmwConfigError("cannot tell every type:\n  " + "\n  ".join(problems))
    return resolved


def read_hints(path: Path) -> dict[str, str]:
    """A hints file: a YAML (or JSON) mapping of name to type."""
    try:
        data = yamltext.safe_load(yamltext.read(path, "hints file"))
    except safefile.UnreadableFile as exc:
        raise RmwConfigError(exc.message) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = SourceRef(Path(path), mark.line + 1, mark.column + 1) if mark else str(path)
        raise RmwConfigError(f"hints are not valid YAML: {getattr(exc, 'problem', exc)}",
                             where) from None
    if not isinstance(data, dict) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise RmwConfigError("hints must map names to types, e.g. /turtle1/cmd_vel: "
                             "geometry_msgs/msg/Twist", str(path))
    return data


# =========================================================================== manifest

@dataclass(frozen=True)
class SideSpec:
    name: str
    port: int
    host: str = "127.0.0.1"


def manifest_from_conf(table: dict[str, int], *, types: dict[str, ResolvedType],
                       side_of: dict[str, str], sides: list[SideSpec], network: str,
                       source: str = "ros_allowed_topics.conf",
                       max_read_length: int = 64, period: float = 1.0) -> str:
    """A commented manifest YAML (profile rmw_desert) for the id table.

    `types` and `side_of` must cover every name of the table but the discovery ones;
    `sides` declares every side `side_of` names. Raises RmwConfigError otherwise.
    """
    entries = [(ident, name) for name, ident in table.items() if name not in RESERVED]
    entries.sort()
    declared = {s.name for s in sides}
    missing_side = [n for _, n in entries if n not in side_of]
    if missing_side:
        raise RmwConfigError("every name needs the side that publishes or serves it; missing: "
                             + ", ".join(missing_side) + " (give --side-of NAME=SIDE)")
    extra = sorted(set(side_of) - {n for _, n in entries})
    if extra:
        raise RmwConfigError("--side-of names what is not in the id table: " + ", ".join(extra))
    undeclared = sorted({side_of[n] for _, n in entries} - declared)
    if undeclared:
        raise RmwConfigError("sides used but not declared: " + ", ".join(undeclared))

    has_discovery = all(name in table for name in RESERVED)
    q = _yaml_scalar
    lines = [
        f"# Started by `uwgen rmw-config import` from the rmw_desert id table {source}.",
        "# Names and ids are the table's and must stay as they are: every rmw_desert node",
        "# on the network reads the same table. Check the types and the sides, set the link",
        "# settings of each side to its DESERT node's max_read_length and period_, then build.",
        f"network: {q(network)}",
        "# rmw_desert's wire format and discovery for every topic and service:",
        "# bools as F4/F5, floats as float32, byte fields left out, no fragmentation.",
        f"profile: {PROFILE}",
    ]
    if not has_discovery:
        lines.append("# The table has no /discovery and /discovery_request: its rmw_desert nodes "
                     "do not announce\n# themselves, and ignore the beacons a bridge sends.")
    lines += ["", "sides:"]
    for side in sides:
        lines.append(f"  {side.name}:")
        if side.host != "127.0.0.1":
            lines.append(f"    host: {q(side.host)}")
        lines.append(f"    port: {side.port}   # the DESERT node's socket port")
        lines.append(f"    link: {{max_read_length: {max_read_length}, period: {period}}}")
    topics = [(i, n) for i, n in entries if not types[n].is_service]
    services = [(i, n) for i, n in entries if types[n].is_service]
    if topics:
        lines += ["", "topics:"]
        for ident, name in topics:
            lines += [f"  - name: {q(name)}", f"    id: {ident}",
                      f"    type: {types[name].full_name}   # {types[name].origin}",
                      f"    publisher: {side_of[name]}"]
    if services:
        lines += ["", "services:"]
        for ident, name in services:
            lines += [f"  - name: {q(name)}", f"    id: {ident}",
                      f"    type: {types[name].full_name}   # {types[name].origin}",
                      f"    server: {side_of[name]}"]
    if not entries:
        lines += ["", "# The id table lists no topic or service besides discovery.",
                  "topics: []"]
    return "\n".join(lines) + "\n"


def _yaml_scalar(value: str) -> str:
    """`value` as a YAML scalar, quoted only when a plain scalar would not round-trip."""
    dumped = yaml.safe_dump(value, default_flow_style=True)
    return dumped.removesuffix("\n...\n").strip()
