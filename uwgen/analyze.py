"""What a manifest costs on the link: `uwgen analyze`.

For every topic and service part, the bits (packed) and bytes (native) of each field,
the smallest, typical and largest payload in each profile, the air time of a message,
and per sending side a link budget: rates times message sizes against the link's
`max_read_length / period`. Everything is computed from the codec IR, the same one the
generator lowers, so the numbers follow the wire format (sections 4, 8, 9). The sizes of
single fields, and what "typical" and "worst" mean, are uwgen.analyze_sizes; control
traffic is uwgen.analyze_control; the text and JSON forms are uwgen.analyze_report.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from uwgen.analyze_control import DESERT_PACKET_OVERHEAD, SideControl, control_costs, whole_payload
from uwgen.analyze_sizes import Size, Sizer, describe
from uwgen.codegen.encodings import Filler
from uwgen.codegen.fingerprint import wire_format_of
from uwgen.codegen.ir import IRBuilder, variant_name
from uwgen.manifest.model import DEFAULT_TAG_BYTES, NATIVE, PACKED, RMW_DESERT, Manifest, takes_part
from uwgen.runtime.wire.envelope import HEAD as ENVELOPE_HEAD, v1_message_size
from uwgen.runtime.wire.envelope import VERSION as ENVELOPE_VERSION
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD, SHORT_OVERHEAD
from uwgen.security.packet_seal import max_overhead

PACKET_ALONE = SHORT_OVERHEAD + ENVELOPE_HEAD   # an envelope link: the short frame, P and W around one message
DEFAULT_BITRATE = 4800.0    # bit/s of DESERT's default modem settings used by the emulator


# --- whole messages and the link ----------------------------------------------------------

@dataclass
class FieldCost:
    path: str
    encoding: str
    bits: Size            # packed
    bytes: Size           # native


@dataclass
class ProfileCost:
    label: str            # 'native', 'native + fields', 'packed + fields', ...
    configured: bool      # what the manifest sends
    payload: Size         # bytes, header included
    frame: Size           # payload + frame bytes


ACTION_KINDS = ("goal", "result", "feedback")   # an action's payloads (wire format 13)


@dataclass
class EntryCost:
    kind: str             # topic, request, response, goal, result, feedback
    name: str
    id: int
    type_name: str
    sender: str           # the side that sends it ('*' for requests: every other side)
    rate: float | None
    fields: list[FieldCost]
    profiles: list[ProfileCost]

    @property
    def configured(self) -> ProfileCost:
        return next(p for p in self.profiles if p.configured)


@dataclass
class SideBudget:
    side: str
    capacity: float                       # bytes per second the link carries
    typical: float                        # bytes per second of rate-limited traffic (typical sizes)
    worst: float | None                   # ... at worst-case sizes (None: unbounded)
    unlimited: list[str] = field(default_factory=list)   # entries with no rate
    schema: float = 0.0                   # bytes per second of periodic schema announcements (included above)
    limited_by: str = "period"            # what sets the capacity: the link's "period" or the modem's "bit rate"
    thinned: list[str] = field(default_factory=list)     # latest-only topics counted below their rate

    @property
    def fits(self) -> bool:
        return self.typical <= self.capacity and (self.worst is None or self.worst <= self.capacity) \
            and not self.unlimited


@dataclass
class Analysis:
    network: str
    bitrate: float
    entries: list[EntryCost]
    budgets: list[SideBudget]
    wire_format: int = ENVELOPE_VERSION     # 1 (rmw_desert on the network) or the envelope's
    control: list[SideControl] = field(default_factory=list)   # discovery, schema announcements
    tag_bytes: int | None = None     # the per-packet tag of a secured envelope link
    mac_notes: list[str] = field(default_factory=list)   # uwgen.mac_budget.mac_warnings
    mac_shares: list[str] = field(default_factory=list)  # uwgen.mac_budget.mac_shares

    def warnings(self) -> list[str]:
        out = list(self.mac_notes)
        for b in self.budgets:
            if b.typical > b.capacity:
                out.append(f"side {b.side}: configured traffic needs {b.typical:.1f} B/s (typical sizes) but its "
                           f"link carries {b.capacity:.1f} B/s (limited by its {b.limited_by}): it cannot fit; "
                           "lower rates or shrink messages")
            elif b.worst is not None and b.worst > b.capacity:
                out.append(f"side {b.side}: at worst-case sizes traffic needs {b.worst:.1f} B/s, over the "
                           f"{b.capacity:.1f} B/s its link carries")
            elif b.worst is None and b.typical > 0:
                out.append(f"side {b.side}: some messages have no size bound (unbounded strings or sequences); "
                           "worst-case traffic is unbounded")
            for name in b.unlimited:
                out.append(f"side {b.side}: {name} has no rate limit; it can take the whole link")
            out += [f"side {b.side}: {line}" for line in b.thinned]
        return out


def air_time(frame_bytes: int, bitrate: float, max_read_length: int) -> float:
    """Seconds one frame occupies the channel: DESERT adds 4 bytes per packet of at most
    max_read_length bytes (wire format section 1)."""
    packets = max(1, math.ceil(frame_bytes / max_read_length))
    return (frame_bytes + DESERT_PACKET_OVERHEAD * packets) * 8 / bitrate


def capacity(max_read_length: int, period: float, bitrate: float) -> tuple[float, str]:
    """(payload bytes per second a side's link carries, what limits it): at most one packet
    of max_read_length bytes per period, and no more than the modem's bit rate can put on
    the air, DESERT's 4 bytes per packet included."""
    by_period = max_read_length / period
    by_bitrate = bitrate / 8 * max_read_length / (max_read_length + DESERT_PACKET_OVERHEAD)
    return (by_period, "period") if by_period <= by_bitrate else (by_bitrate, "bit rate")


from uwgen.mac_budget import capacity_under_mac, mac_shares, mac_warnings  # noqa: E402


def analyze(manifest: Manifest, lookup, bitrate: float = DEFAULT_BITRATE) -> Analysis:
    """The costs of every manifest entry. `lookup(full_name) -> MessageDef`."""
    builder = IRBuilder(lookup)
    sizer = Sizer(builder)
    wire = wire_format_of(manifest)
    sizer.wire = wire
    tag = manifest.security.tag_bytes
    entries: list[EntryCost] = []
    for t in manifest.topics:
        entries.append(_entry(builder, sizer, "topic", t.name, t.id, t.type_name, t.publisher, t.policy.rate,
                              t.type, t.profile, t.fields, variant_name("t", t.id, t.fields), 2,
                              _entry_security(t, wire, tag)))
    for s in manifest.services:
        entries.append(_entry(builder, sizer, "request", s.name, s.id, s.type_name, "*", s.policy.rate,
                              s.type.request, s.profile, s.request_fields,
                              variant_name("q", s.id, s.request_fields), 3,
                              _entry_security(s, wire, tag)))
        entries.append(_entry(builder, sizer, "response", s.name, s.id, s.type_name, s.server, s.policy.rate,
                              s.type.response, s.profile, s.response_fields,
                              variant_name("r", s.id, s.response_fields), 3,
                              _entry_security(s, wire, tag)))
    for a in getattr(manifest, "actions", ()):
        # Goals (and the 3-byte cancels) from every client side; answers (4 bytes), results
        # and latest-only feedback from the server side.
        entries.append(_entry(builder, sizer, "goal", a.name, a.id, a.type_name, "*", a.policy.rate,
                              a.type.goal, a.profile, (), "", 3,
                              _entry_security(a, wire, tag)))
        entries.append(_entry(builder, sizer, "result", a.name, a.id, a.type_name, a.server,
                              a.policy.rate, a.type.result, a.profile, (), "", 4,
                              _entry_security(a, wire, tag)))
        if a.feedback is not None:
            entries.append(_entry(builder, sizer, "feedback", a.name, a.id, a.type_name, a.server,
                                  a.feedback.rate, a.type.feedback, a.profile, (), "", 3,
                                  _entry_security(a, wire, tag)))
    budgets = []
    schema = _schema_rate(manifest)
    for side in manifest.sides.values():
        cap, limit = capacity_under_mac(manifest, side,
                                        *capacity(side.link.max_read_length, side.link.period, bitrate))
        typical, worst, unlimited, thinned = schema, schema, [], []
        packets = cap / side.link.max_read_length      # the most packets a second the side sends
        for e in entries:
            if e.sender not in (side.name, "*") or (e.sender == "*" and _server_of(manifest, e) == side.name):
                continue
            if not takes_part(manifest.entry(e.id), side.name):   # another fleet vehicle's entry
                continue
            if e.rate is None:
                unlimited.append(f"{e.kind} {e.name}")
                continue
            rate = e.rate
            latest = e.kind == "feedback" or (e.kind == "topic"
                                               and manifest.entry(e.id).policy.queue == "latest")
            if latest and rate > packets:
                # A latest-only queue (a topic's, every action's feedback) keeps the newest
                # message alone, so it never leaves more often than its side sends packets:
                # the rest are superseded, by design.
                thinned.append(f"{e.kind} {e.name} (latest) counted at {packets:.2f}/s of its {rate:g}/s: "
                               f"{side.name} sends at most {packets:.2f} packets/s and a latest "
                               "queue sends only the newest message")
                rate = packets
            frame = e.configured.frame
            typical += rate * frame.typical
            worst = None if worst is None or frame.max is None else worst + rate * frame.max
        budgets.append(SideBudget(side.name, cap, typical, worst, unlimited, schema, limit, thinned))
    seal = _secured(wire, tag)
    sealed = (seal.typical, seal.max) if manifest.protected() else (0, 0)
    control = control_costs(manifest, bitrate, wire, sealed)
    return Analysis(manifest.network, bitrate, entries, budgets, wire, control,
                    tag if manifest.protected() and wire != 1 else None, mac_warnings(manifest),
                    mac_shares(manifest))


def _schema_rate(manifest: Manifest) -> float:
    """Bytes per second each side spends on its periodic schema announcements
    (wire format section 10): every id's fingerprint, every `schema_period` seconds."""
    period = getattr(manifest, "schema_period", None)
    schema_id = getattr(manifest, "schema_id", None)
    if schema_id is None or not period:
        return 0.0
    from uwgen.bridge.schema import encode_announcements
    from uwgen.codegen.fingerprint import FINGERPRINT_BYTES
    ids = sorted({e.id for e in (*manifest.topics, *manifest.services,
                                 *getattr(manifest, "actions", ()))})
    wire = wire_format_of(manifest)
    sealed = _secured(wire, manifest.security.tag_bytes)
    signed = sealed.typical if manifest.protected() else 0   # signed with security on
    mrl = min((side.link.max_read_length for side in manifest.sides.values()), default=64)
    size = whole_payload(wire, mrl, sealed.max if signed else 0)
    payloads = encode_announcements(schema_id, [(i, bytes(FINGERPRINT_BYTES)) for i in ids],
                                    request=False, max_payload=size)     # as the bridge splits them
    if wire != 1:     # each in a packet of its own: H instead of kind and id
        return sum(v1_message_size(p, last=True) + PACKET_ALONE + signed for p in payloads) / period
    return sum(len(p) + FRAME_OVERHEAD + signed for p in payloads) / period


# What the secure link adds to a frame (wire format section 12): wire format 1, each payload
# 10 bytes, 23 on sync frames; an envelope link (section 12.2), each packet 8 bytes, 21 on sync
# packets, 23 on one that also asks for a sync. A frame here is one message alone.
_SECURED = Size(10, 10, 23)
_UNSECURED = Size(0, 0, 0)


def _secured(wire: int, tag_bytes: int = DEFAULT_TAG_BYTES) -> Size:
    """What the seal adds: per payload (wire format 1), or per packet with the manifest's
    `security: {tag_bytes}` (an envelope link: the tag, K and T on sync packets, C when asking)."""
    if wire == 1:
        return _SECURED
    return Size(tag_bytes, tag_bytes, max_overhead(tag_bytes))


def _entry_security(entry, wire: int = 1, tag_bytes: int = DEFAULT_TAG_BYTES) -> Size:
    return _UNSECURED if getattr(entry, "security", "off") == "off" else _secured(wire, tag_bytes)


def _server_of(manifest: Manifest, entry: EntryCost) -> str | None:
    return next((s.server for s in (*manifest.services, *getattr(manifest, "actions", ()))
                 if s.id == entry.id), None)


def _entry(builder, sizer, kind, name, ident, type_name, sender, rate, msg, profile, fields, variant,
           header_items, security: Size = _UNSECURED) -> EntryCost:
    wire = getattr(sizer, "wire", 1)
    if wire != 1:                         # H: one byte for ids up to 31, else two
        head = Size(1, 1, 1) if ident <= 31 else Size(2, 2, 2)
    else:
        head = Size(2, 2, 2) if ident < 24 else Size(3, 3, 3)
    if kind in ACTION_KINDS:
        head = head + Size(header_items - 2, header_items - 2, header_items - 2)  # handle (+ status)
    elif header_items == 3:
        head = head + Size(1, 2, 9)   # the seq: any unsigned, typically under 256
    configured = builder.codec(msg, profile, fields, variant)
    options = [(NATIVE, (), "", "native")]
    if profile == RMW_DESERT:
        options.append((RMW_DESERT, (), "", "rmw_desert"))
    if fields:
        options += [(NATIVE, fields, variant, "native + fields"), (PACKED, fields, variant, "packed + fields")]
    elif kind not in ACTION_KINDS:     # actions travel in profile native only
        options.append((PACKED, (), "", "packed"))
    costs = []
    for prof, f, var, label in options:
        ct = builder.codec(msg, prof, f, var)
        body = sizer.message(ct)
        if prof == PACKED:
            body = Size(*(None if b is None else _packed_bytes(b, wire) for b in (body.min, body.typical, body.max)))
        payload = head + body
        alone = PACKET_ALONE if wire != 1 else FRAME_OVERHEAD
        frame = payload + security + Size(alone, alone, alone)
        costs.append(ProfileCost(label, ct is configured, payload, frame))
    leaves = []
    for leaf in configured.root.leaves():
        if isinstance(leaf.encoding, Filler):
            continue
        leaves.append(FieldCost(leaf.path, describe(leaf.encoding), sizer.bits(leaf.encoding),
                                sizer.bytes(leaf.encoding, NATIVE if profile == PACKED else profile)))
    return EntryCost(kind, name, ident, type_name, sender, rate, leaves, costs)


def _packed_bytes(bits: int, wire: int = 1) -> int:
    """Bytes of the packed fields: the bits padded to bytes, after a byte string head in wire
    format 1 (an envelope says the length once)."""
    n = (bits + 7) // 8
    return n if wire != 1 else n + (1 if n < 24 else 2 if n < 256 else 3)
