"""Checks of the manifest as a whole: unique names, the reserved ids (fragment_id, schema_id,
rmw_desert's discovery ids) and what `repair` needs."""
from __future__ import annotations

from dataclasses import dataclass

import yaml

from uwgen.manifest.model import RMW_DESERT, RMW_DISCOVERY_ID, RMW_DISCOVERY_REQUEST_ID, Manifest
from uwgen.manifest.nodes import ManifestError, Reader

ID_RANGE = (1, 255)


@dataclass
class IdUse:
    """Who holds an id, for duplicate and reservation messages."""

    what: str
    node: yaml.Node


def unique_names(items: list, kind: str) -> None:
    seen: dict[str, object] = {}
    for item in items:
        if item.name in seen:
            first = seen[item.name]
            raise ManifestError(item.where, f"{kind} {item.name} is declared twice (first at line {first.where.line})")
        seen[item.name] = item


def reserved_id(r: Reader, ids: dict[int, IdUse], node: yaml.Node, key: str) -> int | None:
    """`fragment_id` / `schema_id`: None (null), or an id no entry uses."""
    if isinstance(node, yaml.ScalarNode) and r.value(node) is None:
        return None
    ident = r.integer(node, key, *ID_RANGE)
    if ident in ids:
        user = ids[ident]
        raise r.error(node, f"{key} {ident} collides with the id of {user.what} (line {r.where(user.node).line}); it must be an id no topic or service uses")
    return ident


def schema_id(r: Reader, ids: dict[int, IdUse], node: yaml.Node, fragment_id: int | None) -> int | None:
    ident = reserved_id(r, ids, node, "schema_id")
    if ident is not None and ident == fragment_id:
        raise r.error(node, f"schema_id {ident} is also the fragment_id; the two reserved ids must differ")
    return ident


def check_repair(r: Reader, manifest: Manifest, repair_nodes: dict[str, yaml.Node]) -> None:
    """`repair` needs fragments: a fragment_id, and the native profile."""
    for entry in (*manifest.topics, *manifest.services):
        if not entry.policy.repair:
            continue
        kind = "topic" if entry in manifest.topics else "service"
        node = repair_nodes[f"{kind} {entry.name}"]
        if manifest.fragment_id is None:
            raise r.error(node, f"repair of {kind} {entry.name} needs fragments: set fragment_id "
                          f"(repair fragments travel on it)")
        if entry.profile == RMW_DESERT:
            raise r.error(node, f"repair of {kind} {entry.name}: profile rmw_desert messages are "
                          f"never fragmented (rmw_desert nodes cannot reassemble them); use "
                          f"profile native or remove repair")


def check_rmw_reserved(r: Reader, ids: dict[int, IdUse], manifest: Manifest, top: dict) -> None:
    user = next(t for t in (*manifest.topics, *manifest.services) if t.profile == RMW_DESERT)
    reason = f"while any topic or service uses profile rmw_desert ({user.name} at line {user.where.line} does)"
    reserved = {RMW_DISCOVERY_ID: "/discovery", RMW_DISCOVERY_REQUEST_ID: "/discovery_request"}
    for ident, topic in reserved.items():
        if ident in ids:
            use = ids[ident]
            raise r.error(use.node, f"id {ident} of {use.what} is reserved for rmw_desert's {topic} {reason}")
    if manifest.fragment_id in reserved:
        raise r.error(top["fragment_id"][1], f"fragment_id {manifest.fragment_id} is reserved for rmw_desert's {reserved[manifest.fragment_id]} {reason}")
    if manifest.schema_id in reserved:
        raise r.error(top["schema_id"][1], f"schema_id {manifest.schema_id} is reserved for rmw_desert's {reserved[manifest.schema_id]} {reason}")


def check_mixed_commands(manifest: Manifest) -> None:
    """A manifest with an rmw_desert entry makes the whole link speak wire format 1 (rmw_desert
    nodes read nothing else, and they hear every packet of the network): no packet time, no
    per-packet seal, no delivery once. A service or action of another profile would then lose
    its age bound and its protection against repeats, so the mix is refused for commands (docs/
    seams.md section 8): a held or repeated call could run late or twice."""
    user = next(t for t in (*manifest.topics, *manifest.services) if t.profile == RMW_DESERT)
    for entry in (*manifest.services, *manifest.actions):
        if getattr(entry, "profile", None) == RMW_DESERT:
            continue
        kind = "service" if entry in manifest.services else "action"
        raise ManifestError(entry.where, (
            f"{kind} {entry.name} is a command in profile {getattr(entry, 'profile', 'native')}, "
            f"but {user.name} (line {user.where.line if user.where else '?'}) is in profile "
            f"rmw_desert, so the whole link speaks wire format 1: no packet time (a held call "
            f"could run after its timeout), no per-packet seal and no delivery once (a repeated "
            f"one could run twice). Put the rmw_desert entries in a network of their own, or "
            + ("give this service profile rmw_desert (its rmw_desert semantics, stated in "
               "docs/wire-format.md)" if kind == "service" else
               "carry this action on a network without rmw_desert entries (actions are native only)")))
