"""What one side's bridge does, worked out from the generated package before any ROS starts.

The direction of every manifest entry is decided here, once, from the manifest alone:
a topic is *outgoing* on the side that publishes it (the bridge subscribes locally and
sends) and *incoming* everywhere else (the bridge receives and publishes locally). A
bridge therefore never has a subscription and a publisher on the same topic, so it can
never take its own publication and send it back over the link. Services likewise: the
serving side calls the real service, every other side offers a stand-in service.

Actions likewise: the server side calls the real action server through an action client,
every other side offers a stand-in action server.

An entry that names its peers (a fleet vehicle's own entries, uwgen.manifest.fleet) is
bridged by those sides only: vehicle 2 neither offers vehicle 1's services nor publishes
its telemetry. The others' entries stay known (`overheard`): their packets are heard on
the shared channel, their ids are in the seal's authenticated data and in schema
announcements, and what arrives for them is counted `overheard`, not `unknown_id`.

The generated package is duck-typed (see notes/contracts.md): `MANIFEST` with `network`,
`sides` and `fragment_id`; `TOPICS`, `SERVICES` and `ACTIONS` (packages generated before
actions have none) mapping id to codec objects.
"""
from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import ModuleType
from typing import Any

from uwgen.manifest.model import (NATIVE, PACKED, RMW_DESERT, LinkConfig, LinkPolicy,  # RMW_DESERT: discovery, seqs 1..999
                                  handle_range, takes_part)

# What a stand-in service does when its bridged call gets no response in time.
TIMEOUT_REPLY_NONE = "none"        # send no response: the client's own timeout detects it
TIMEOUT_REPLY_DEFAULT = "default"  # send a default-constructed response (and log the error)
TIMEOUT_REPLIES = (TIMEOUT_REPLY_NONE, TIMEOUT_REPLY_DEFAULT)
# Link channel key of an action's feedback: never a wire id (those are 1..255).
FEEDBACK_KEY_BASE = 256

class PlanError(Exception):
    """The bridge cannot be set up as asked (unknown side, bad option): exit status 2."""


@dataclass(frozen=True)
class BridgeOptions:
    """Where this side's DESERT node is and what its link can carry."""

    host: str = "127.0.0.1"
    port: int = 4000
    link: LinkConfig = field(default_factory=LinkConfig)
    status_period: float = 2.0      # seconds between ~/status messages (0: none)
    timeout_reply: str = TIMEOUT_REPLY_NONE
    stats_file: Path | None = None  # also write the status JSON here (periodically and at exit)
    key_file: Path | None = None    # network key (default: the manifest's security key_file)
    security_state: Path | None = None  # the side's lock file (default: next to the key file)
    record: Path | None = None      # MCAP recording of this side (uwgen.bridge.recorder)
    record_max_bytes: int = 64 * 1024 * 1024   # a recording file this big is rotated
    record_keep: int = 8            # newest recording files kept (0: all)
    diagnostics_period: float = 1.0  # seconds between /diagnostics messages (0: none)

    def unparameterised(self) -> dict:
        """The options no ROS parameter overrides (the node passes them through as they are)."""
        return {k: getattr(self, k) for k in ("stats_file", "key_file", "security_state", "record",
                                              "record_max_bytes", "record_keep", "diagnostics_period")}

    def check(self) -> "BridgeOptions":
        if not 0 < self.port < 65536:
            raise PlanError(f"port {self.port} is not a TCP port (1..65535)")
        if not 1 <= self.link.max_read_length <= 4096:
            raise PlanError(f"max_read_length {self.link.max_read_length} must be 1..4096 "
                            "(DESERT crashes above 4096)")
        if not self.link.period > 0:
            raise PlanError(f"period {self.link.period} must be > 0 seconds")
        if self.timeout_reply not in TIMEOUT_REPLIES:
            raise PlanError(f"timeout reply {self.timeout_reply!r} must be one of "
                            f"{', '.join(TIMEOUT_REPLIES)}")
        if self.status_period < 0:
            raise PlanError("status period must be >= 0")
        if self.diagnostics_period < 0:
            raise PlanError("diagnostics period must be >= 0")
        return self


@dataclass
class BridgePlan:
    network: str
    side: str
    outgoing_topics: list[Any]    # TopicCodec: this side publishes; subscribe locally, send
    incoming_topics: list[Any]    # TopicCodec: another side publishes; receive, publish locally
    called_services: list[Any]    # ServiceCodec served elsewhere: offer a stand-in service here
    served_services: list[Any]    # ServiceCodec served here: call the real local service
    fragment_id: int | None
    defaults: BridgeOptions
    offered_actions: list[Any] = field(default_factory=list)  # ActionCodec served elsewhere: stand-in server here
    served_actions: list[Any] = field(default_factory=list)   # ActionCodec served here: call the real server
    action_handles: dict[int, tuple[int, int]] = field(default_factory=dict)  # offered id -> this side's handles
    schema_id: int | None = None          # reserved id of schema announcements (None: off)
    schema_period: float | None = None    # seconds between periodic announcements
    schema_digest: bytes = b""            # the generated package's SCHEMA_DIGEST
    security: Any = None          # manifest.model.SecurityPlan, None when nothing is protected
    manifest_source: str = ""     # the manifest as the build named it (relative to where it ran)
    manifest_path: Path | None = None   # where that manifest is now (relative key files are from its folder)
    sender_id: int = 0            # W of wire format 2: the security sender id, else the side's index
    side_ids: dict[str, int] = field(default_factory=dict)   # every side's sender id (W)
    mac: Any = None               # manifest.model.MacConfig (None: mode none)
    # Codecs of the entries other sides bridge (fleet peers): topics, services, actions.
    overheard_topics: list[Any] = field(default_factory=list)
    overheard_services: list[Any] = field(default_factory=list)
    overheard_actions: list[Any] = field(default_factory=list)

    @classmethod
    def from_package(cls, package: ModuleType | Any, side: str,
                     manifest_path: Path | None = None) -> "BridgePlan":
        """The plan of `side`. `manifest_path`: the manifest the package was built from, as
        given on the command line (default: found from the package's place, see
        buildinfo.own_manifest)."""
        manifest = package.MANIFEST
        sides = manifest.sides
        if side not in sides:
            raise PlanError(f"side {side!r} is not in manifest network {manifest.network!r} "
                            f"(sides: {', '.join(sorted(sides)) or 'none'})")
        entry = sides[side]
        every = [sorted(group.values(), key=lambda e: e.id)
                 for group in (package.TOPICS, package.SERVICES, getattr(package, "ACTIONS", {}))]
        topics, services, actions = ([e for e in group if takes_part(e, side)] for group in every)
        return cls(
            network=manifest.network,
            side=side,
            outgoing_topics=[t for t in topics if t.publisher == side],
            incoming_topics=[t for t in topics if t.publisher != side],
            called_services=[s for s in services if s.server != side],
            served_services=[s for s in services if s.server == side],
            fragment_id=getattr(manifest, "fragment_id", None),
            defaults=BridgeOptions(host=entry.host, port=entry.port, link=entry.link),
            offered_actions=[a for a in actions if a.server != side],
            served_actions=[a for a in actions if a.server == side],
            action_handles={a.id: handle_range(list(getattr(a, "peers", ()) or sides), side, a.server)
                            for a in actions if a.server != side},
            schema_id=getattr(manifest, "schema_id", None),
            schema_period=getattr(manifest, "schema_period", None),
            schema_digest=getattr(manifest, "schema_digest", b""),
            security=getattr(manifest, "security", None),
            manifest_source=getattr(manifest, "source", "") or "",
            manifest_path=Path(manifest_path).resolve() if manifest_path is not None else _own_manifest(package),
            sender_id=_sender_id(manifest, side),
            side_ids={s: _sender_id(manifest, s) for s in sides},
            mac=getattr(manifest, "mac", None),
            overheard_topics=[t for t in every[0] if not takes_part(t, side)],
            overheard_services=[s for s in every[1] if not takes_part(s, side)],
            overheard_actions=[a for a in every[2] if not takes_part(a, side)],
        )

    def channels(self) -> list[tuple[int, LinkPolicy, str, bool]]:
        """Link channels this side sends on, as (id, policy, name, whole): its outgoing topics,
        every service and action it takes part in (requests from the calling side, responses
        from the serving side), and the feedback of the actions it serves (key
        FEEDBACK_KEY_BASE + id, latest-only). `whole`: an rmw_desert entry, never fragmented
        (actions are native only)."""
        chans = [(t.id, t.policy, t.name, is_rmw_desert(t)) for t in self.outgoing_topics]
        chans += [(s.id, s.policy, s.name, is_rmw_desert(s))
                  for s in (*self.called_services, *self.served_services)]
        chans += [(a.id, a.policy, a.name, False) for a in (*self.offered_actions, *self.served_actions)]
        chans += [(FEEDBACK_KEY_BASE + a.id, a.feedback_policy, f"{a.name} feedback", False)
                  for a in self.served_actions if a.feedback_policy is not None]
        return sorted(chans, key=lambda c: c[0])

    @property
    def overheard(self) -> list[Any]:
        """Every entry this side hears but does not bridge, by id."""
        return sorted((*self.overheard_topics, *self.overheard_services, *self.overheard_actions),
                      key=lambda e: e.id)

    @property
    def topics(self) -> list[Any]:
        """Every topic of the manifest, by id."""
        return sorted((*self.outgoing_topics, *self.incoming_topics), key=lambda t: t.id)

    @property
    def services(self) -> list[Any]:
        """Every service of the manifest, by id."""
        return sorted((*self.called_services, *self.served_services), key=lambda s: s.id)

    @property
    def uses_rmw_desert(self) -> bool:
        """True when some entry is in profile rmw_desert: the bridge then runs discovery."""
        return any(is_rmw_desert(e) for e in (*self.topics, *self.services))

    @property
    def wire_format(self) -> int:
        """2 (one envelope per packet) unless an entry is in profile rmw_desert: rmw_desert nodes
        on the network read wire format 1 only, so the whole link keeps it."""
        return 1 if self.uses_rmw_desert else 2

    @property
    def packed_ids(self) -> frozenset[int]:
        """Ids in profile packed: in wire format 2 their fields travel without a byte-string head."""
        return frozenset(e.id for e in (*self.topics, *self.services)
                         if getattr(e, "profile", NATIVE) == PACKED)

    def link_options(self) -> dict[str, Any]:
        """Keyword arguments of `Link` that the plan decides (wire format and its sender id)."""
        if self.wire_format == 1:
            return {}
        return {"wire_format": 2, "sender_id": self.sender_id, "packed_ids": self.packed_ids}

    def options(self, host: str | None = None, port: int | None = None,
                max_read_length: int | None = None, period: float | None = None,
                **extra: Any) -> BridgeOptions:
        """The manifest's side entry, overridden by whatever is not None."""
        d = self.defaults
        link = LinkConfig(
            max_read_length=d.link.max_read_length if max_read_length is None else int(max_read_length),
            period=d.link.period if period is None else float(period))
        opts = replace(d, host=d.host if host is None else host,
                       port=d.port if port is None else int(port), link=link,
                       **{k: v for k, v in extra.items() if v is not None})
        opts.check()
        # The floor of this network's packets (envelope, reliability, seal, a fragment), also
        # when --max-read-length overrides the manifest: below it the link cannot send at all.
        from uwgen.linkfloor import check_option
        problem = check_option(link.max_read_length, self.wire_format,
                               getattr(self.security, "tag_bytes", None) if self.security else None,
                               mac_bytes(self.mac))
        if problem:
            raise PlanError(problem)
        return opts

    def entry_names(self) -> list[str]:
        """Every topic, service and action this side bridges, by name."""
        return [e.name for e in (*self.outgoing_topics, *self.incoming_topics, *self.called_services,
                                 *self.served_services, *self.offered_actions, *self.served_actions)]

    def describe(self) -> str:
        def names(items):
            return ", ".join(f"{i.name}#{i.id}" for i in items) or "-"
        return (f"network {self.network} side {self.side}: sends {names(self.outgoing_topics)}; "
                f"receives {names(self.incoming_topics)}; calls {names(self.called_services)}; "
                f"serves {names(self.served_services)}"
                + (f"; offers actions {names(self.offered_actions)}; serves actions "
                   f"{names(self.served_actions)}" if self.offered_actions or self.served_actions
                   else ""))


def mac_bytes(mac: Any) -> int:
    """What the MAC's C items add to a packet (mode turns), for the floor of max_read_length."""
    from uwgen.runtime.link.mac import TurnMac
    return TurnMac.overhead if getattr(mac, "mode", "none") == "turns" else 0


def _sender_id(manifest: Any, side: str) -> int:
    senders = getattr(getattr(manifest, "security", None), "senders", None) or {}
    if side in senders:
        return senders[side]
    return sorted(manifest.sides).index(side) % 16


def _own_manifest(package: Any) -> Path | None:
    from uwgen.buildinfo import own_manifest
    return own_manifest(package) if getattr(package, "__file__", None) else None


def is_rmw_desert(entry: Any) -> bool:
    """Whether a codec is in profile rmw_desert (codecs without `profile` are native)."""
    return getattr(entry, "profile", NATIVE) == RMW_DESERT


def import_package(name: str, package_dir: Path | None = None) -> ModuleType:
    """Import a generated package by name, from `package_dir` if given (put first on sys.path)."""
    if package_dir is not None:
        folder = str(Path(package_dir).resolve())
        if folder not in sys.path:
            sys.path.insert(0, folder)
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name != name:
            raise
        where = f" in {package_dir}" if package_dir else ""
        raise PlanError(f"generated package {name!r} not found{where}: run `uwgen build` first") from None
