"""What an emulated DESERT network looks like: nodes, their sockets, the link and the channel.

A `Scenario` is plain data, validated once when built (`Scenario(...)` raises
`ScenarioError` on nonsense), so the simulation core and the socket shell never meet a
bad value.  `load_scenario(path)` reads the YAML form (msg_samples/scenarios/*.yaml) and
reports mistakes as `file:line:column: message`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import yaml

from uwgen import safefile, yamltext
from uwgen.emulator.motion import PoseFeed, Position, Track, check_waypoints
from uwgen.emulator.physics import SnrModel
from uwgen.emulator.slots import check_slots

MAX_READ_LENGTH_LIMIT = 4096  # DESERT crashes above this (measured on DESERT 4.0.0)
BROADCAST = "*"               # a node's dest: every other node (DESERT's IP broadcast)


class ScenarioError(ValueError):
    """A scenario that DESERT would refuse or crash on; str() is `file:line:column: message`
    when it comes from a file."""

    def __init__(self, message: str, where: str | None = None):
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}" if where else message)


@dataclass(frozen=True)
class NodeSpec:
    """One DESERT node: its application socket, where it is, and where it sends.

    period / max_read_length default to the scenario's.  slot is its TDMA slot (default:
    its index among the nodes).  phase shifts its send ticks (DESERT nodes of one scenario
    start together, so by default every node ticks at the same instants).
    waypoints, if given, move the node: (t, x, y, z) points it passes in straight lines
    (uwgen.emulator.motion); pose_topic drives it live from a ROS topic instead (its
    position until the first message is `position`, or the waypoints').
    """

    name: str
    port: int = 0                                   # 0: an ephemeral port (see Emulator.port)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)   # metres
    dest: str | None = None                         # default: the next node (a ring); "*": all
    period: float | None = None
    max_read_length: int | None = None
    slot: int | None = None
    phase: float = 0.0
    waypoints: tuple = ()
    pose_topic: PoseFeed | None = None


@dataclass(frozen=True)
class TdmaSpec:
    """UW/TDMA as DESERT runs it (uwgen.emulator.tdma): a frame of `slots` slots, equal or as
    `weights` (manual mode); a node starts packets only in its ON window (its slot minus
    `guard`), up to `max_packet_per_slot` of them, and a packet may end past the window; its
    MAC queue holds `queue_size` packets (a new one is dropped when it is full, counted)."""

    frame: float = 1.0
    guard: float = 0.05
    slots: int | None = None      # default: the number of nodes
    max_packet_per_slot: int = 1000     # DESERT's default is 1; its ROV sample sets 1000
    queue_size: int = 1000              # DESERT's queue_size_ (default 10)
    weights: tuple[int, ...] = ()       # per slot, in slot order; () : equal slots (fair mode)


@dataclass(frozen=True)
class Scenario:
    nodes: list[NodeSpec] = field(default_factory=list)
    period: float = 0.2            # DESERT's period_: one packet per node per period
    max_read_length: int = 64      # bytes per packet
    bitrate: float = 4800.0        # bit/s on the acoustic channel
    per: float = 0.0               # fixed packet error rate, on top of the channel model
    seed: int = 1
    sound_speed: float = 1500.0    # m/s
    header_bytes: int = 4          # UDP + IP header bytes DESERT adds to each packet
    listen_time: float = 0.01      # CSMA-ALOHA carrier listen before each transmission...
    listen_jitter: float = 0.01    # ...plus uniform(0, listen_jitter) s (DESERT's random part)
    snr: SnrModel | None = None    # None: no SNR losses (only `per` and collisions)
    tdma: TdmaSpec | None = None   # None: CSMA-ALOHA
    start_delay: float = 0.0       # seconds before the sockets listen (DESERT's start time)

    def __post_init__(self) -> None:
        _validate(self)

    # -- derived values the core uses -------------------------------------------------
    def node(self, name: str) -> NodeSpec:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(f"no node named {name!r} (nodes: {', '.join(self.names())})")

    def names(self) -> list[str]:
        return [n.name for n in self.nodes]

    def dest_of(self, name: str) -> str:
        names = self.names()
        spec = self.node(name)
        if spec.dest is not None:
            return spec.dest
        return names[(names.index(name) + 1) % len(names)]

    def period_of(self, name: str) -> float:
        p = self.node(name).period
        return self.period if p is None else p

    def max_read_length_of(self, name: str) -> int:
        m = self.node(name).max_read_length
        return self.max_read_length if m is None else m

    def slot_of(self, name: str) -> int:
        s = self.node(name).slot
        return self.names().index(name) if s is None else s

    def tdma_slots(self) -> int:
        assert self.tdma is not None
        return self.tdma.slots if self.tdma.slots is not None else len(self.nodes)

    def distance(self, a: str, b: str, t: float = 0.0) -> float:
        return math.dist(self.position_at(a, t), self.position_at(b, t))

    def position_at(self, name: str, t: float) -> Position:
        """Where `name` is `t` seconds after the start (its waypoints, else its position)."""
        spec = self.node(name)
        if spec.waypoints:
            return Track(spec.waypoints).at(t)
        return spec.position

    def moves(self, name: str) -> bool:
        """Does `name` move (waypoints or a live pose topic)?"""
        spec = self.node(name)
        return bool(spec.waypoints) or spec.pose_topic is not None

    def tx_time(self, payload_bytes: int) -> float:
        """Seconds on the air for a packet carrying `payload_bytes` (plus DESERT's header)."""
        return (payload_bytes + self.header_bytes) * 8.0 / self.bitrate


def _validate(s: Scenario) -> None:
    def bad(msg: str) -> None:
        raise ScenarioError(msg)

    if len(s.nodes) < 2:
        bad(f"a scenario needs at least 2 nodes, got {len(s.nodes)}")
    names = [n.name for n in s.nodes]
    for n in s.nodes:
        if not isinstance(n.name, str) or not n.name or n.name == BROADCAST:
            bad(f"node name must be a non-empty string other than {BROADCAST!r}, got {n.name!r}")
    dup = {x for x in names if names.count(x) > 1}
    if dup:
        bad(f"node names must be unique: {', '.join(sorted(dup))} repeated")
    ports = [n.port for n in s.nodes if n.port]
    dup_ports = {p for p in ports if ports.count(p) > 1}
    if dup_ports:
        bad(f"ports must be unique: {', '.join(map(str, sorted(dup_ports)))} repeated")
    for value, what in ((s.period, "period"), (s.bitrate, "bitrate"),
                        (s.sound_speed, "sound_speed")):
        if not _finite(value) or value <= 0:
            bad(f"{what} must be a positive number, got {value!r}")
    _check_read_length(s.max_read_length, "max_read_length", bad)
    if not _finite(s.per) or not 0.0 <= s.per <= 1.0:
        bad(f"per must be in [0, 1], got {s.per!r}")
    if not isinstance(s.header_bytes, int) or s.header_bytes < 0:
        bad(f"header_bytes must be an integer >= 0, got {s.header_bytes!r}")
    if not _finite(s.listen_time) or s.listen_time < 0:
        bad(f"listen_time must be >= 0, got {s.listen_time!r}")
    if not _finite(s.listen_jitter) or s.listen_jitter < 0:
        bad(f"listen_jitter must be >= 0, got {s.listen_jitter!r}")
    if not _finite(s.start_delay) or s.start_delay < 0:
        bad(f"start_delay must be >= 0, got {s.start_delay!r}")
    if not isinstance(s.seed, int):
        bad(f"seed must be an integer, got {s.seed!r}")
    for n in s.nodes:
        where = f"node {n.name}"
        if not isinstance(n.port, int) or not 0 <= n.port <= 65535:
            bad(f"{where}: port must be 0..65535, got {n.port!r}")
        if len(n.position) != 3 or not all(_finite(c) for c in n.position):
            bad(f"{where}: position must be three numbers (x, y, z in metres), got {n.position!r}")
        if n.dest is not None and n.dest != BROADCAST:
            if n.dest not in names:
                bad(f"{where}: dest {n.dest!r} is not a node (nodes: {', '.join(names)})")
            if n.dest == n.name:
                bad(f"{where}: dest must be another node, not itself")
        if n.period is not None and (not _finite(n.period) or n.period <= 0):
            bad(f"{where}: period must be a positive number, got {n.period!r}")
        if n.max_read_length is not None:
            _check_read_length(n.max_read_length, f"{where}: max_read_length", bad)
        if not _finite(n.phase) or n.phase < 0:
            bad(f"{where}: phase must be >= 0, got {n.phase!r}")
        if n.waypoints:
            problem = check_waypoints(n.waypoints)
            if problem:
                bad(f"{where}: waypoints: {problem}")
        if n.pose_topic is not None and not isinstance(n.pose_topic, PoseFeed):
            bad(f"{where}: pose_topic must be a PoseFeed, got {n.pose_topic!r}")
    if s.tdma is not None:
        t = s.tdma
        if not _finite(t.frame) or t.frame <= 0:
            bad(f"tdma.frame must be a positive number, got {t.frame!r}")
        if not _finite(t.guard) or t.guard < 0:
            bad(f"tdma.guard must be >= 0, got {t.guard!r}")
        slots = s.tdma_slots()
        if not isinstance(slots, int) or slots < 1:
            bad(f"tdma.slots must be a positive integer, got {slots!r}")
        for n in s.nodes:
            slot = s.slot_of(n.name)
            if not isinstance(slot, int) or not 0 <= slot < slots:
                bad(f"node {n.name}: tdma slot must be 0..{slots - 1}, got {slot!r}")
        check_slots(t, slots, bad)
        for key in ("max_packet_per_slot", "queue_size"):
            value = getattr(t, key)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                bad(f"tdma.{key} must be a positive integer, got {value!r}")


def _check_read_length(value: Any, what: str, bad) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        bad(f"{what} must be a positive integer, got {value!r}")
    if value > MAX_READ_LENGTH_LIMIT:
        bad(f"{what} {value} is above {MAX_READ_LENGTH_LIMIT}: DESERT crashes with it")


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


# ---------------------------------------------------------------------------------------
# YAML
# ---------------------------------------------------------------------------------------

_TOP_KEYS = {f.name for f in fields(Scenario)}
_NODE_KEYS = {f.name for f in fields(NodeSpec)}
_TDMA_KEYS = {f.name for f in fields(TdmaSpec)}
_SNR_KEYS = {f.name for f in fields(SnrModel)}
_POSE_KEYS = {f.name for f in fields(PoseFeed)}


class _Doc:
    """A YAML document as python values, remembering where each value came from."""

    def __init__(self, path: Path):
        self.path = path
        self.marks: dict[tuple, Any] = {}

    def where(self, key_path: tuple) -> str:
        # The closest recorded ancestor: a missing key is reported at its parent mapping.
        while key_path not in self.marks and key_path:
            key_path = key_path[:-1]
        mark = self.marks.get(key_path)
        if mark is None:
            return str(self.path)
        return f"{self.path}:{mark.line + 1}:{mark.column + 1}"

    def build(self, node: yaml.Node, key_path: tuple = ()) -> Any:
        self.marks[key_path] = node.start_mark
        if isinstance(node, yaml.MappingNode):
            out: dict[str, Any] = {}
            for k, v in node.value:
                if not isinstance(k, yaml.ScalarNode):
                    raise ScenarioError("keys must be plain names", self._at(k.start_mark))
                key = k.value
                if key in out:
                    raise ScenarioError(f"key {key!r} appears twice",
                                        self._at(k.start_mark))
                out[key] = self.build(v, key_path + (key,))
                self.marks[key_path + (key, "<key>")] = k.start_mark
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self.build(v, key_path + (i,)) for i, v in enumerate(node.value)]
        return yaml.safe_load(yaml.serialize(node))

    def _at(self, mark) -> str:
        return f"{self.path}:{mark.line + 1}:{mark.column + 1}"


def load_scenario(path: Path | str, base_nodes: list[NodeSpec] | None = None) -> Scenario:
    """Read a YAML scenario; raise ScenarioError (`file:line:column: message`) on any mistake.

    With `base_nodes` (a manifest's sides) the file only adds to them: its `nodes` are
    optional, each must name a base node, and may not change a base node's port, period
    or max_read_length (`uwgen emulate -m`)."""
    path = Path(path)
    try:
        text = yamltext.read(path, "scenario")
    except safefile.UnreadableFile as exc:
        if exc.line:
            raise ScenarioError(exc.reason, f"{path}:{exc.line}:{exc.column}") from None
        raise ScenarioError(exc.message) from None
    doc = _Doc(path)
    try:
        root = yaml.compose(text, Loader=yamltext.Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark else str(path)
        raise ScenarioError(f"not valid YAML: {getattr(exc, 'problem', exc)}", where) from None
    if root is None:
        raise ScenarioError("the scenario is empty", str(path))
    data = doc.build(root)
    return scenario_from_dict(data, doc, base_nodes)


FIXED_BY_BASE = ("port", "period", "max_read_length")


def scenario_from_dict(data: Any, doc: _Doc | None = None,
                       base_nodes: list[NodeSpec] | None = None) -> Scenario:
    """Build a Scenario from the YAML structure (a dict); errors name the offending key."""
    def where(*key_path) -> str | None:
        return doc.where(tuple(key_path)) if doc else None

    def fail(msg: str, *key_path) -> ScenarioError:
        return ScenarioError(msg, where(*key_path) or (".".join(map(str, key_path)) or None))

    if not isinstance(data, dict):
        raise fail("a scenario is a mapping of settings with a `nodes` list")
    _reject_unknown(data, _TOP_KEYS, (), fail)
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key in ("nodes", "snr", "tdma"):
            continue
        kwargs[key] = value
    nodes_raw = data.get("nodes")
    if base_nodes is not None and nodes_raw is None:
        nodes_raw = []
    if not isinstance(nodes_raw, list):
        raise fail("`nodes` must be a list of nodes (each with at least a name)", "nodes")
    nodes = []
    for i, raw in enumerate(nodes_raw):
        if not isinstance(raw, dict):
            raise fail("each node is a mapping with at least `name`", "nodes", i)
        _reject_unknown(raw, _NODE_KEYS, ("nodes", i), fail)
        if "name" not in raw:
            raise fail("node has no `name`", "nodes", i)
        node_kwargs = dict(raw)
        node_kwargs["name"] = str(node_kwargs["name"])
        if "dest" in node_kwargs and node_kwargs["dest"] is not None:
            node_kwargs["dest"] = str(node_kwargs["dest"])
        if "position" in node_kwargs:
            pos = node_kwargs["position"]
            if not isinstance(pos, list) or len(pos) not in (1, 2, 3):
                raise fail("position is a list of up to three numbers [x, y, z] in metres",
                           "nodes", i, "position")
            node_kwargs["position"] = tuple(list(pos) + [0.0] * (3 - len(pos)))
        if "waypoints" in node_kwargs:
            wps = node_kwargs["waypoints"]
            problem = check_waypoints(wps)
            if problem:
                raise fail(problem, "nodes", i, "waypoints")
            node_kwargs["waypoints"] = tuple(tuple(w) for w in wps)
        if node_kwargs.get("pose_topic") is not None:
            feed = node_kwargs["pose_topic"]
            if not isinstance(feed, dict):
                raise fail("pose_topic is a mapping: topic, type, scale, offset",
                           "nodes", i, "pose_topic")
            _reject_unknown(feed, _POSE_KEYS, ("nodes", i, "pose_topic"), fail)
            if "offset" in feed:
                off = feed["offset"]
                if not isinstance(off, list) or len(off) not in (1, 2, 3):
                    raise fail("offset is a list of up to three numbers [x, y, z] in metres",
                               "nodes", i, "pose_topic", "offset")
                feed = {**feed, "offset": tuple(list(off) + [0.0] * (3 - len(off)))}
            try:
                node_kwargs["pose_topic"] = PoseFeed(**feed)
            except (TypeError, ValueError) as exc:
                raise fail(str(exc), "nodes", i, "pose_topic") from None
        if base_nodes is not None:
            nodes.append(_onto_base(node_kwargs, base_nodes, ("nodes", i), fail))
            continue
        try:
            nodes.append(NodeSpec(**node_kwargs))
        except TypeError as exc:
            raise fail(str(exc), "nodes", i) from None
    if base_nodes is not None:
        merged = {n.name: n for n in nodes}
        nodes = [merged.get(b.name, b) for b in base_nodes]
    kwargs["nodes"] = nodes
    for key, cls, known in (("snr", SnrModel, _SNR_KEYS), ("tdma", TdmaSpec, _TDMA_KEYS)):
        if key not in data or data[key] is None:
            continue
        raw = data[key]
        if raw is True:             # `snr: true` turns the model on with its defaults
            raw = {}
        if not isinstance(raw, dict):
            raise fail(f"`{key}` must be a mapping of its settings", key)
        _reject_unknown(raw, known, (key,), fail)
        try:
            kwargs[key] = cls(**raw)
        except (TypeError, ValueError) as exc:
            raise fail(f"{key}: {exc}", key) from None
    try:
        return Scenario(**kwargs)
    except ScenarioError as exc:
        # Point at the most specific key the message names, else at the top.
        raise ScenarioError(exc.message, _locate(exc.message, data, where)) from None
    except TypeError as exc:
        raise fail(str(exc)) from None


def _onto_base(node_kwargs: dict, base_nodes: list[NodeSpec], key_path: tuple,
               fail) -> NodeSpec:
    """A scenario node laid onto the base node of the same name (see load_scenario)."""
    base = {b.name: b for b in base_nodes}
    name = node_kwargs["name"]
    if name not in base:
        raise fail(f"node {name} is not a side of the manifest (sides: {', '.join(base)})",
                   *key_path, "name")
    spec = base[name]
    for key in FIXED_BY_BASE:
        if key in node_kwargs and node_kwargs[key] not in (None, getattr(spec, key)):
            raise fail(f"node {name}: {key} {node_kwargs[key]!r} contradicts the manifest "
                       f"({getattr(spec, key)!r}): leave {key} to the manifest",
                       *key_path, key)
    try:
        return replace(spec, **{k: v for k, v in node_kwargs.items() if k != "name"})
    except TypeError as exc:
        raise fail(str(exc), *key_path) from None


def _reject_unknown(raw: dict, known: set[str], key_path: tuple, fail) -> None:
    for key in raw:
        if key not in known:
            raise fail(f"unknown setting {key!r} (known: {', '.join(sorted(known))})",
                       *key_path, key, "<key>")


def _locate(message: str, data: dict, where) -> str | None:
    """Best-effort position for a validation message: the node or key it is about."""
    nodes = data.get("nodes") or []
    if message.startswith("node "):
        name = message[5:].split(":", 1)[0]
        for i, raw in enumerate(nodes):
            if isinstance(raw, dict) and str(raw.get("name")) == name:
                for key in raw:
                    if f"{key} " in message or f" {key}" in message.split(":", 1)[-1][:20]:
                        return where("nodes", i, key)
                return where("nodes", i)
    for key in data:
        if message.startswith(f"{key} ") or message.startswith(f"{key}."):
            return where(key)
    return where()
