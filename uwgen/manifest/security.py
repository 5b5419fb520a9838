"""The manifest's security keys (wire-format.md section 12), read with file:line:column errors.

    security: {mode: off | sign | encrypt, key_file: PATH,    # network default
               tag_bytes: 4 | 6 | 8}                       # per-packet tag (default 8)
    sides: {vehicle: {port: 4001, sender_id: 2}, ...}        # one sender id per side
    topics: [{..., security: off | sign | encrypt}]          # per-entry override

Keys are never in the manifest: `key_file` names the file `uwgen keygen` wrote (relative
to the manifest's folder). The rmw_desert profile cannot be protected (an rmw_desert node
could not read the payload), so an rmw_desert entry whose mode is not off is refused.

`tag_bytes` is the length of the one AES-CCM tag each packet of a wire format 2 link carries
(wire-format.md section 12.2 states the forgery odds of each). A manifest with an rmw_desert
entry speaks wire format 1, whose per-payload seal keeps its 8-byte tag byte for byte: a
`tag_bytes` other than 8 there is refused rather than silently ignored.
"""
from __future__ import annotations

from dataclasses import replace

import yaml

from uwgen.manifest.model import (DEFAULT_TAG_BYTES, MAX_SENDER_ID, RMW_DESERT, SECURITY_MODES,
                                  TAG_BYTES, Manifest, Security)
from uwgen.manifest.nodes import Reader

SECURITY_KEYS = ("mode", "key_file", "tag_bytes")


def mode(r: Reader, node: yaml.Node, what: str) -> str:
    """off | sign | encrypt. YAML 1.1 reads a bare `off` as false: take the written text."""
    if isinstance(node, yaml.ScalarNode) and node.value in SECURITY_MODES and node.style is None:
        return node.value
    return r.choice(node, what, SECURITY_MODES)


def network_security(r: Reader, node: yaml.Node) -> Security:
    fields = r.mapping(node, "security", SECURITY_KEYS)
    sec = Security()
    if "mode" in fields:
        sec = replace(sec, mode=mode(r, fields["mode"][1], "security mode"))
    if "key_file" in fields:
        path = r.string(fields["key_file"][1], "security key_file")
        if not path.strip():
            raise r.error(fields["key_file"][1], "security key_file must name a file")
        sec = replace(sec, key_file=path)
    if "tag_bytes" in fields:
        sec = replace(sec, tag_bytes=tag_bytes(r, fields["tag_bytes"][1]))
    return sec


def tag_bytes(r: Reader, node: yaml.Node) -> int:
    allowed = ", ".join(map(str, TAG_BYTES))
    value = r.value(node)
    if isinstance(value, bool) or not isinstance(value, int) or value not in TAG_BYTES:
        shown = node.value if isinstance(node, yaml.ScalarNode) else r.describe(node)
        raise r.error(node, f"security tag_bytes must be one of {allowed} (bytes of AES-CCM tag "
                      f"per packet; 8 unless the link is too slow for it); got {shown!r}")
    return value


def sender_id(r: Reader, node: yaml.Node, side: str) -> int:
    return r.integer(node, f"sender_id of side '{side}'", 0, MAX_SENDER_ID)


class SecurityCheck:
    """Collects the nodes security errors point at while the manifest is read, then checks."""

    def __init__(self, r: Reader):
        self.r = r
        self.block: yaml.Node | None = None          # the network's security: mapping
        self.mode_node: yaml.Node | None = None
        self.sender_nodes: dict[str, yaml.Node] = {}
        self.side_nodes: dict[str, yaml.Node] = {}
        self.entry_nodes: dict[str, yaml.Node] = {}  # entry name -> its own security: node
        self.tag_node: yaml.Node | None = None        # the network's tag_bytes: value

    def entry_mode(self, entries: dict, label: str, name: str, default: str) -> str:
        if "security" not in entries:
            return default
        node = entries["security"][1]
        self.entry_nodes[name] = node
        return mode(self.r, node, f"security of {label}")

    def finish(self, manifest: Manifest, root: yaml.Node, senders: dict[str, int]) -> Manifest:
        r = self.r
        seen: dict[int, str] = {}
        for side, ident in senders.items():
            if ident in seen:
                raise r.error(self.sender_nodes[side], f"sender_id {ident} of side '{side}' is "
                              f"already the sender_id of side '{seen[ident]}'; each side needs its own")
            seen[ident] = side
        manifest.security = replace(manifest.security, senders=dict(senders))
        self._tag_bytes(manifest)
        if not manifest.protected():
            return manifest
        for entry in (*manifest.topics, *manifest.services):
            if entry.security != "off" and entry.profile == RMW_DESERT:
                kind = "topic" if entry in manifest.topics else "service"
                node = self.entry_nodes.get(entry.name) or self.mode_node
                raise r.error(node, f"{kind} {entry.name} (line {entry.where.line}) is in profile "
                              f"rmw_desert, which cannot be signed or encrypted (rmw_desert nodes "
                              f"could not read it): give it `security: off` or use profile native")
        if manifest.security.key_file is None:
            where = self.block if self.block is not None else root
            raise r.error(where, "security is on for some topics, services or actions but no key is named: "
                          "add `security: {key_file: PATH}` (create the key with `uwgen keygen PATH`)")
        for side, node in self.side_nodes.items():
            if side not in senders and side not in self.sender_nodes:   # not one that is wrong
                raise r.error(node, f"side '{side}' needs a sender_id (0..{MAX_SENDER_ID}, one per "
                              "side) because security is on")
        return manifest

    def _tag_bytes(self, manifest: Manifest) -> None:
        """A tag length other than 8 only where it applies: wire format 1 links (any
        rmw_desert entry) seal each payload with section 12's 8-byte tag, unchanged."""
        if manifest.security.tag_bytes == DEFAULT_TAG_BYTES or not manifest.uses_rmw_desert():
            return
        first = next(e for e in (*manifest.topics, *manifest.services) if e.profile == RMW_DESERT)
        raise self.r.error(self.tag_node, f"security tag_bytes {manifest.security.tag_bytes} applies "
                           f"to wire format 4 links only, and {first.name} (line {first.where.line}) "
                           f"is in profile rmw_desert, so this link speaks wire format 1, whose "
                           f"per-payload seal has an 8-byte tag: remove tag_bytes (or give 8)")
