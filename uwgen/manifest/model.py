"""The validated manifest: what `uwgen.manifest.loader` returns.

Every key of the YAML is documented in `msg_samples/manifest-reference.yaml`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:   # annotations only: this module stays stdlib-only (generated packages carry it)
    from uwgen.idl.model import ActionDef, MessageDef, ServiceDef, SourceRef

NATIVE = "native"            # uwgen's own compact encoding (wire format section 4)
RMW_DESERT = "rmw_desert"    # what rmw_desert nodes send and decode (section 6)
PACKED = "packed"            # one bit-packed CBOR byte string after the header (section 9)
PROFILES = (NATIVE, RMW_DESERT, PACKED)
QUEUE_KINDS = ("latest", "fifo")
RELIABILITY = ("reliable", "best_effort")
DURABILITY = ("volatile", "transient_local")
FIFO_DEFAULT_DEPTH = 4   # queue depth of a fifo queue whose depth is not given
SCHEMA_PERIOD_DEFAULT = 600.0   # seconds between schema announcements (besides connect and request)
SECURITY_MODES = ("off", "sign", "encrypt")   # docs/wire-format.md section 12
MAX_SENDER_ID = 15       # sender ids of the secure link are 4 bits
TAG_BYTES = (4, 6, 8)    # AES-CCM tag lengths a wire format 2 link may use (wire-format.md 12.2)
DEFAULT_TAG_BYTES = 8
# Action goal handles on the wire are 0..ACTION_HANDLES-1: one CBOR byte each (wire format
# section 13). Defined here, where the manifest shares them among clients; the codecs import it.
ACTION_HANDLES = 24

# Ids rmw_desert uses for its discovery topics; reserved while any profile is rmw_desert.
RMW_DISCOVERY_ID = 1
RMW_DISCOVERY_REQUEST_ID = 2


@dataclass(frozen=True)
class LinkPolicy:
    """How one topic or service may use the acoustic link (enforced by the link scheduler)."""

    rate: float | None = None   # most messages per second over the link; None: no limit
    queue: str = "latest"       # "latest": keep only the newest; "fifo": keep `depth`, oldest first
    depth: int = 1              # queue depth (always 1 for "latest")
    ttl: float | None = None    # seconds; older messages are dropped, never sent stale
    priority: int = 0           # a larger share of a busy link (weight priority + 1)
    repair: int = 0             # repair fragments per fragmented message (erasure code; 0: none)
    strict: bool = False        # served before every non-strict entry whenever it has a message
    reliable: bool = False      # acknowledged and re-sent until its ttl (topics with
                                # `reliability: reliable`; wire format 15); never rmw_desert
    cut: bool = True            # a message that does not fit the rest of a packet may be cut
                                # and finished in the next (wire format 14.2; never a reliable
                                # entry or one with a max age)


@dataclass(frozen=True)
class Qos:
    """QoS of the local ROS publisher/subscriber the bridge creates."""

    reliability: str = "reliable"
    durability: str = "volatile"
    depth: int = 10


@dataclass(frozen=True)
class LinkConfig:
    """What a side's DESERT node can carry; the connection paces writes to it."""

    max_read_length: int = 64   # bytes per acoustic packet (DESERT's max_read_length)
    period: float = 1.0         # seconds between packets (DESERT's period_)

    @property
    def bytes_per_second(self) -> float:
        return self.max_read_length / self.period


MAC_MODES = ("none", "tdma", "turns")   # how the sides share the channel (docs/emulator.md, MACs)
DEFAULT_TURN_PACKETS = 4                 # packets a turn grant allows when the manifest names none
SOUND_SPEED = 1500.0                     # m/s: what `range` becomes in seconds


@dataclass(frozen=True)
class MacConfig:
    """The manifest's `mac:` section: how the sides share the one acoustic channel.

    - `none`: every side writes when its period allows; DESERT's MAC (stock CSMA-ALOHA) sorts
      it out, and packets of two sides may collide;
    - `tdma`: DESERT runs UW/TDMA in fair mode: a `frame` of one slot per side in `slots`
      order, each ON for slot - `guard`, at most `max_packet_per_slot` packets in a slot and
      `queue_size` packets in DESERT's MAC queue. The bridge writes no more than its slot
      drains per frame. `weights` (side -> a positive integer, default 1) make slots
      unequal: a side's slot is its weight's share of the frame, one contiguous slot each
      (DESERT's manual mode: setStartTime, setSlotDuration);
    - `turns`: DESERT keeps its stock MAC; the `leader` side grants the turn to one side at a
      time in a C item, that side answers after hearing it and ends its turn with another
      (docs/wire-format.md section 16). `packets`: how many packets a turn allows, per side.
    `bitrate` (bit/s) and `range` (m, the farthest two sides are apart) size air times and
    the first timers until round trips are measured.
    """

    mode: str = "none"
    bitrate: float = 4800.0
    range: float = 1000.0
    frame: float = 1.0
    guard: float = 0.05
    slots: tuple[str, ...] = ()                     # tdma: sides in slot order
    max_packet_per_slot: int = 1
    queue_size: int = 10
    weights: tuple[tuple[str, int], ...] = ()       # tdma: (side, weight) where not 1
    leader: str = ""                                # turns
    packets: tuple[tuple[str, int], ...] = ()       # turns: (side, packets per turn)

    @property
    def slot(self) -> float:
        """The shortest slot (all of them when no side has a weight)."""
        return min((self.slot_length(s) for s in self.slots), default=self.frame)

    def slot_of(self, side: str) -> int:
        return self.slots.index(side)

    def weight(self, side: str) -> int:
        return dict(self.weights).get(side, 1)

    def slot_weights(self) -> tuple[int, ...]:
        """Every slot's weight, in slot order."""
        return tuple(self.weight(s) for s in self.slots)

    def slot_length(self, side: str) -> float:
        """Seconds of `side`'s slot: its weight's share of the frame."""
        return self.frame * self.weight(side) / max(1, sum(self.slot_weights()))

    def slot_start(self, side: str) -> float:
        """Seconds from the frame's start to `side`'s slot (DESERT's setStartTime)."""
        before = sum(self.weight(s) for s in self.slots[:self.slot_of(side)])
        return self.frame * before / max(1, sum(self.slot_weights()))

    def turn_packets(self, side: str) -> int:
        return dict(self.packets).get(side, DEFAULT_TURN_PACKETS)

    @property
    def delay(self) -> float:
        """Seconds a packet travels across `range`."""
        return self.range / SOUND_SPEED


@dataclass(frozen=True)
class Side:
    name: str
    host: str = "127.0.0.1"
    port: int = 4000
    link: LinkConfig = field(default_factory=LinkConfig)
    where: SourceRef | None = None


# Kinds of field encodings (wire format section 8; manifest key `fields:`).
QUANTIZE = "quantize"                  # min, max, step: an unsigned index on a grid
STATIC = "static"                      # not sent; the decoder fills `value`
OMIT = "omit"                          # not sent; the decoder leaves the type's default
TIME_OF_DAY = "time_of_day"            # builtin_interfaces/Time as seconds of the day
TIME_SINCE_EPOCH = "time_since_epoch"  # builtin_interfaces/Time as an offset from `epoch`
ENUM = "enum"                          # one of `values`, sent as its index
MAX_LENGTH = "max_length"              # a string bound tighter than the .msg's
MAX_COUNT = "max_count"                # a sequence bound tighter than the .msg's


@dataclass(frozen=True)
class FieldEncoding:
    """How one field (or every element of an array, path ending in `[]`) is sent.

    Numbers are exact: `min`, `max` and `step` are Fractions of the decimal values the
    manifest wrote (0.1 is 1/10, not the binary float nearest to it).
    """

    path: str                          # 'linear.x', 'header.stamp', 'cell_voltage[]'
    kind: str                          # one of the kinds above
    min: Fraction | None = None        # QUANTIZE
    max: Fraction | None = None        # QUANTIZE; TIME_SINCE_EPOCH: the span in seconds
    step: Fraction | None = None       # QUANTIZE; TIME_*: the resolution in seconds
    clamp: bool = False                # QUANTIZE: saturate out-of-range values instead of refusing
    value: object = None               # STATIC
    values: tuple = ()                 # ENUM
    bound: int | None = None           # MAX_LENGTH, MAX_COUNT
    epoch: int | None = None           # TIME_SINCE_EPOCH: unix seconds
    where: SourceRef | None = None

    @property
    def count(self) -> int | None:
        """How many codes the wire carries (nmax + 1), for the kinds that send an index."""
        if self.kind == QUANTIZE:
            return int((self.max - self.min) / self.step) + 1
        if self.kind == TIME_OF_DAY:
            return int(86400 / self.step)
        if self.kind == TIME_SINCE_EPOCH:
            return int(self.max / self.step) + 1
        if self.kind == ENUM:
            return len(self.values)
        return None


@dataclass(frozen=True)
class Topic:
    name: str                   # ROS name, e.g. /turtle1/cmd_vel
    id: int                     # 1..255, unique across topics and services
    type_name: str              # pkg/msg/Name
    type: MessageDef
    publisher: str              # the side whose local graph publishes it
    policy: LinkPolicy = field(default_factory=LinkPolicy)
    qos: Qos = field(default_factory=Qos)
    profile: str = NATIVE
    where: SourceRef | None = None
    fields: tuple[FieldEncoding, ...] = ()   # field encodings (manifest `fields:`)
    security: str = "off"       # off | sign | encrypt (the network's mode unless set here)
    peers: tuple[str, ...] = ()  # the sides that take part (a fleet vehicle's entry); (): every side


@dataclass(frozen=True)
class Service:
    name: str                   # ROS name, e.g. /vehicle/set_pen
    id: int
    type_name: str              # pkg/srv/Name
    type: ServiceDef
    server: str                 # the side whose local graph serves it
    timeout: float = 30.0       # seconds a bridged call waits for its response
    policy: LinkPolicy = field(default_factory=lambda: LinkPolicy(queue="fifo", depth=FIFO_DEFAULT_DEPTH))
    profile: str = NATIVE
    where: SourceRef | None = None
    request_fields: tuple[FieldEncoding, ...] = ()    # manifest `request_fields:`
    response_fields: tuple[FieldEncoding, ...] = ()   # manifest `response_fields:`
    security: str = "off"       # off | sign | encrypt (the network's mode unless set here)
    peers: tuple[str, ...] = ()  # the sides that take part (a fleet vehicle's entry); (): every side


@dataclass(frozen=True)
class Security:
    """The network's `security:` block and the sides' sender ids (wire-format.md 12)."""

    mode: str = "off"                      # default mode of topics and services
    key_file: str | None = None            # as written in the manifest (relative: to its folder)
    senders: dict[str, int] = field(default_factory=dict)   # side -> sender id (0..15)
    tag_bytes: int = DEFAULT_TAG_BYTES     # AES-CCM tag per packet (wire format 2; 4, 6 or 8)

    def modes(self, entries) -> dict[int, str]:
        """id -> mode of the protected entries among `entries`."""
        return {e.id: e.security for e in entries if e.security != "off"}


@dataclass(frozen=True)
class SecurityPlan:
    """What a generated package keeps of the security set-up: the bridge needs nothing else."""

    key_file: str                          # as in the manifest (relative: to its folder)
    senders: dict[str, int]                # side -> sender id
    modes: dict[int, str]                  # protected id -> sign | encrypt
    tag_bytes: int = DEFAULT_TAG_BYTES     # the per-packet tag's length (wire format 2)
    # protected id -> the schema fingerprint the per-packet seal authenticates, when tag_bytes
    # is not 8 (the fingerprint without its tag item; codegen.fingerprint.seal_fingerprints)
    seal_fingerprints: dict[int, bytes] = field(default_factory=dict)


MAX_GOALS_LIMIT = ACTION_HANDLES // 2   # goals in flight per action, at most


def takes_part(entry, side: str) -> bool:
    """Whether `side` bridges `entry` (a manifest entry or its codec): every side does,
    unless the entry names its peers (a fleet vehicle's own entries: the vehicle and the
    sides that lead the fleet)."""
    peers = getattr(entry, "peers", ())
    return not peers or side in peers


@dataclass(frozen=True)
class Fleet:
    """The manifest's `fleet:` section, expanded (msg_samples/manifest-reference.yaml):
    vehicles carrying the same interfaces, each as a side of its own."""

    vehicles: tuple[str, ...]        # side names, in turn order (vehicle n is vehicles[n - 1])
    namespaces: dict[str, str]       # vehicle -> its namespace, e.g. /auv1
    leaders: tuple[str, ...]         # the sides declared under `sides:` (the surface): peers of every vehicle
    id_stride: int                   # vehicle n's ids: the template's + (n - 1) * id_stride

    def vehicle_of(self, entry) -> str | None:
        """The vehicle a fleet entry belongs to (None: an entry of the whole network)."""
        return next((p for p in getattr(entry, "peers", ()) if p in self.vehicles), None)


def handle_range(sides: list[str], side: str, server: str) -> tuple[int, int]:
    """The goal handles (first, last) client side `side` uses for an action served by
    `server`: the 24 handles are split evenly between the client sides (in name order),
    so that goals of two client sides never share a handle (wire format 13)."""
    clients = sorted(s for s in sides if s != server)
    size = ACTION_HANDLES // max(1, len(clients))
    first = clients.index(side) * size
    return first, first + size - 1


@dataclass(frozen=True)
class Action:
    """A ROS 2 action bridged as goal, cancel, answer, feedback and result payloads on one id."""

    name: str                   # ROS name, e.g. /vehicle/go_to
    id: int
    type_name: str              # pkg/action/Name
    type: ActionDef
    server: str                 # the side whose local graph runs the real action server
    accept_timeout: float = 10.0   # seconds for the answer to a goal or a cancel
    result_timeout: float = 600.0  # seconds an accepted goal may run before it is aborted
    max_goals: int = 4          # goals in flight at once; more are rejected
    # goals and cancels (client side), answers and results (server side)
    policy: LinkPolicy = field(default_factory=lambda: LinkPolicy(queue="fifo", depth=FIFO_DEFAULT_DEPTH))
    feedback: LinkPolicy | None = field(default_factory=lambda: LinkPolicy(rate=0.2))  # latest only; None: not sent
    profile: str = NATIVE
    where: SourceRef | None = None
    security: str = "off"       # off | sign | encrypt: every payload on this id (wire format 12)
    peers: tuple[str, ...] = ()  # the sides that take part (a fleet vehicle's entry); (): every side


@dataclass
class Manifest:
    network: str
    source: Path | None
    profile: str = NATIVE                        # default profile of topics and services
    package: str = ""                            # generated package name (default uwgen_<network>)
    sides: dict[str, Side] = field(default_factory=dict)
    topics: list[Topic] = field(default_factory=list)
    services: list[Service] = field(default_factory=list)
    actions: list[Action] = field(default_factory=list)
    fragment_id: int | None = None               # reserved id for fragments of payloads > 255 bytes
    schema_id: int | None = None                 # reserved id for schema announcements (wire format 10)
    schema_period: float | None = SCHEMA_PERIOD_DEFAULT  # seconds between announcements; None: connect/request only
    security: Security = field(default_factory=Security)
    fleet: Fleet | None = None                   # the `fleet:` section, when there is one
    mac: MacConfig = field(default_factory=MacConfig)

    def entry(self, id: int) -> Topic | Service | Action | None:
        for item in (*self.topics, *self.services, *self.actions):
            if item.id == id:
                return item
        return None

    def security_plan(self) -> SecurityPlan | None:
        """None when nothing is protected."""
        if not self.protected():
            return None
        modes = self.security.modes((*self.topics, *self.services, *self.actions))
        if self.schema_id is not None:
            # Signed too: a forged announcement would make the far side refuse an id.
            modes[self.schema_id] = "sign"
        return SecurityPlan(self.security.key_file or "", dict(sorted(self.security.senders.items())),
                            dict(sorted(modes.items())), self.security.tag_bytes)

    def protected(self) -> bool:
        """Whether any topic, service or action is signed or encrypted."""
        return any(e.security != "off" for e in (*self.topics, *self.services, *self.actions))

    def uses_rmw_desert(self) -> bool:
        return any(t.profile == RMW_DESERT for t in (*self.topics, *self.services))
