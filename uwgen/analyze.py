"""What a manifest costs on the link: `uwgen analyze`.

For every topic and service part, the bits (packed) and bytes (native) of each field,
the smallest, typical and largest payload in each profile, the air time of a message,
and per sending side a link budget: rates times message sizes against the link's
`max_read_length / period`. Everything is computed from the codec IR, the same one the
generator lowers, so the numbers follow the wire format (sections 4, 8, 9).

"Typical" is a stated convention, not a measurement: indices at the middle of their grid,
float32 values that need single precision and float64 values that need double, strings of
8 bytes (or their bound), sequences of 4 elements (or their bound). "Worst" takes every field at its
largest; it is None (unbounded) when a string or sequence has no bound.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from uwgen.codegen.encodings import (
    Absent, Bool, BoolArray, ByteScalar, Enumerated, Filler, MessageArray, Number, NumberArray, Octets,
    Quantized, Static, Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, IRBuilder, variant_name
from uwgen.idl.model import ArrayKind
from uwgen.manifest.model import DEFAULT_TAG_BYTES, NATIVE, PACKED, RMW_DESERT, Manifest
from uwgen.runtime.wire.bits import text_width
from uwgen.analyze_control import SideControl, control_costs, format_control, whole_payload
from uwgen.codegen.fingerprint import wire_format_of
from uwgen.runtime.wire.envelope import HEAD as ENVELOPE_HEAD, v1_message_size
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD
from uwgen.security.packet_seal import SYNC_BYTES, max_overhead

TYPICAL_TEXT = 8            # bytes of a typical string
TYPICAL_COUNT = 4           # elements of a typical sequence
DESERT_PACKET_OVERHEAD = 4  # bytes DESERT adds per packet (UDP and IP headers; wire format section 1)
PACKET_ALONE = FRAME_OVERHEAD + ENVELOPE_HEAD   # wire format 2: frame, P and W around one message
DEFAULT_BITRATE = 4800.0    # bit/s of DESERT's default modem settings used by the emulator


@dataclass(frozen=True)
class Size:
    """Smallest, typical and largest size of something (largest None: unbounded)."""
    min: int
    typical: int
    max: int | None

    def __add__(self, other: "Size") -> "Size":
        top = None if self.max is None or other.max is None else self.max + other.max
        return Size(self.min + other.min, self.typical + other.typical, top)

    def times(self, lo: int, typ: int, hi: int | None) -> "Size":
        top = None if hi is None or self.max is None else self.max * hi
        return Size(self.min * lo, self.typical * typ, top)


ZERO = Size(0, 0, 0)


def cbor_uint(n: int) -> int:
    """Bytes of CBOR's shortest unsigned integer n."""
    return 1 if n < 24 else 2 if n < 0x100 else 3 if n < 0x10000 else 5 if n < 0x100000000 else 9


def _smaller(a: Size, b: Size) -> Size:
    """The size of whichever of two forms the encoder picks, the smaller each time."""
    top = b.max if a.max is None else a.max if b.max is None else min(a.max, b.max)
    return Size(min(a.min, b.min), min(a.typical, b.typical), top)


def _counts(array: ArrayKind, size: int | None) -> tuple[int, int, int | None]:
    if array is ArrayKind.FIXED:
        return size, size, size
    if array is ArrayKind.BOUNDED:
        return 0, min(size, TYPICAL_COUNT), size
    return 0, TYPICAL_COUNT, None


def _index_max(enc) -> int:
    if isinstance(enc, Enumerated):
        return len(enc.values) - 1
    if isinstance(enc, TimeOfDay):
        return enc.count - 1
    return enc.nmax


def describe(enc) -> str:
    """A short human description of a leaf encoding."""
    if isinstance(enc, Quantized):
        step = (enc.high - enc.low) / enc.nmax
        return f"{float(enc.low):g}..{float(enc.high):g} step {float(step):g}{' clamp' if enc.clamp else ''}"
    if isinstance(enc, Enumerated):
        return f"one of {len(enc.values)} values"
    if isinstance(enc, TimeOfDay):
        return f"time of day, step {enc.step_ns / 1e9:g} s"
    if isinstance(enc, TimeSinceEpoch):
        return f"time since epoch, step {enc.step_ns / 1e9:g} s"
    if isinstance(enc, Static):
        return f"static {enc.value!r}"
    if isinstance(enc, Absent):
        return "not sent"
    if isinstance(enc, Number):
        return enc.prim
    if isinstance(enc, Text):
        return "string" + (f"<={enc.bound}" if enc.bound is not None else "")
    return enc.kind.replace("_", " ")


class Sizer:
    """Sizes of codec IR leaves in bits (packed) or bytes (native, rmw_desert)."""

    def __init__(self, builder: IRBuilder):
        self.builder = builder

    def message(self, ct: CodecType) -> Size:
        total = ZERO
        for leaf in ct.root.leaves():
            total = total + self.leaf(leaf.encoding, ct.profile)
        return total

    def leaf(self, enc, profile: str) -> Size:
        return self.bits(enc) if profile == PACKED else self.bytes(enc, profile)

    # --- packed: bits -------------------------------------------------------------------

    def bits(self, enc) -> Size:
        if isinstance(enc, (Absent, Static)):
            return ZERO
        if isinstance(enc, Filler) or isinstance(enc, Bool):
            return Size(1, 1, 1)
        if isinstance(enc, ByteScalar):
            return Size(8, 8, 8)
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch)):
            return Size(enc.bits, enc.bits, enc.bits)
        if isinstance(enc, Number):
            if enc.is_float:
                return Size(18, 34, 34) if enc.prim == "float32" else Size(18, 66, 66)
            lo, hi = enc.range
            w = (hi - lo).bit_length()
            return Size(w, w, w)
        if isinstance(enc, Text):
            return self._text_bits(enc)
        prefix = self._prefix_bits(enc.array, enc.size) if hasattr(enc, "array") else ZERO
        if isinstance(enc, (Quantized, Enumerated)):
            one = Size(enc.bits, enc.bits, enc.bits)
            if enc.array is ArrayKind.NONE:
                return one
            return prefix + one.times(*_counts(enc.array, enc.size))
        if isinstance(enc, Octets):
            return prefix + Size(8, 8, 8).times(*_counts(enc.array, enc.size))
        if isinstance(enc, NumberArray):
            one = self.bits(Number(enc.prim, enc.code))
        elif isinstance(enc, BoolArray):
            one = Size(1, 1, 1)
        elif isinstance(enc, TextArray):
            one = self._text_bits(enc.text)
        elif isinstance(enc, MessageArray):
            one = self.message(self.builder.by_key(enc.type_key, PACKED))
        else:
            raise AssertionError(enc)
        return prefix + one.times(*_counts(enc.array, enc.size))

    @staticmethod
    def _prefix_bits(array: ArrayKind, size: int | None) -> Size:
        if array is ArrayKind.FIXED:
            return ZERO
        if array is ArrayKind.BOUNDED:
            w = size.bit_length()
            return Size(w, w, w)
        return Size(8, 8, None)    # a varint: 8 bits per 7 bits of count

    @staticmethod
    def _text_bits(enc: Text) -> Size:
        if enc.bound is None:
            return Size(8, 8 + 8 * TYPICAL_TEXT, None)
        w = text_width(enc.bound)
        return Size(w, w + 8 * min(enc.bound, TYPICAL_TEXT), w + 8 * 4 * enc.bound)

    # --- native / rmw_desert: bytes -----------------------------------------------------

    def bytes(self, enc, profile: str) -> Size:
        if isinstance(enc, (Absent, Static)):
            return ZERO
        if isinstance(enc, (Filler, Bool)):
            return Size(1, 1, 1)
        if isinstance(enc, ByteScalar):
            return Size(1, 2, 2)
        if isinstance(enc, (Quantized, Enumerated, TimeOfDay, TimeSinceEpoch)) and \
                getattr(enc, "array", ArrayKind.NONE) is ArrayKind.NONE:
            top = _index_max(enc)
            return Size(1, cbor_uint(top // 2), cbor_uint(top))
        if isinstance(enc, Number):
            if enc.is_float:
                return Size(3, 5, 5) if enc.code == "f" else Size(3, 9, 9)
            lo, hi = enc.range
            return Size(1, 1, cbor_uint(max(hi, -1 - lo)))
        if isinstance(enc, Text):
            return self._text_bytes(enc)
        counts = _counts(enc.array, enc.size)
        count = ZERO if enc.array is ArrayKind.FIXED and not getattr(enc, "fixed_count", False) else \
            Size(1, cbor_uint(counts[1]), None if counts[2] is None else cbor_uint(counts[2]))
        if isinstance(enc, Octets):
            return count + Size(1, 1, 1).times(*counts)
        if isinstance(enc, (Quantized, Enumerated)):
            top = _index_max(enc)
            one = Size(1, cbor_uint(top // 2), cbor_uint(top))
        elif isinstance(enc, NumberArray):
            one = self.bytes(Number(enc.prim, enc.code), profile)
        elif isinstance(enc, BoolArray):
            one = Size(1, 1, 1)
        elif isinstance(enc, TextArray):
            one = self._text_bytes(enc.text)
        elif isinstance(enc, MessageArray):
            one = self.message(self.builder.by_key(enc.type_key, profile))
        else:
            raise AssertionError(enc)
        items = count + one.times(*counts)
        if isinstance(enc, NumberArray) and enc.tag is not None:   # or one typed array (4.1)
            def typed(k: int) -> int:
                return 2 + cbor_uint(enc.width * k) + enc.width * k
            lo, typ, hi = counts
            return _smaller(items, Size(typed(lo), typed(typ), None if hi is None else typed(hi)))
        return items

    @staticmethod
    def _text_bytes(enc: Text) -> Size:
        if enc.bound is None:
            return Size(1, 1 + TYPICAL_TEXT, None)
        top = enc.max_bytes if enc.max_bytes is not None else 4 * enc.bound
        return Size(1, 1 + min(enc.bound, TYPICAL_TEXT), cbor_uint(top) + top)


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
    wire_format: int = 2
    control: list[SideControl] = field(default_factory=list)   # discovery, schema announcements
    tag_bytes: int | None = None     # the per-packet tag of a secured wire format 2 link

    def warnings(self) -> list[str]:
        out = []
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
        cap, limit = capacity(side.link.max_read_length, side.link.period, bitrate)
        typical, worst, unlimited = schema, schema, []
        for e in entries:
            if e.sender not in (side.name, "*") or (e.sender == "*" and _server_of(manifest, e) == side.name):
                continue
            if e.rate is None:
                unlimited.append(f"{e.kind} {e.name}")
                continue
            frame = e.configured.frame
            typical += e.rate * frame.typical
            worst = None if worst is None or frame.max is None else worst + e.rate * frame.max
        budgets.append(SideBudget(side.name, cap, typical, worst, unlimited, schema, limit))
    seal = _secured(wire, tag)
    sealed = (seal.typical, seal.max) if manifest.protected() else (0, 0)
    control = control_costs(manifest, bitrate, wire, sealed)
    return Analysis(manifest.network, bitrate, entries, budgets, wire, control,
                    tag if manifest.protected() and wire == 2 else None)


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
    if wire == 2:     # each in a packet of its own: H instead of kind and id
        return sum(v1_message_size(p, last=True) + PACKET_ALONE + signed for p in payloads) / period
    return sum(len(p) + FRAME_OVERHEAD + signed for p in payloads) / period


# What the secure link adds to a frame (wire format section 12): wire format 1, each payload
# 10 bytes, 23 on sync frames; wire format 2 (section 12.2), each packet 8 bytes, 21 on sync
# packets, 23 on one that also asks for a sync. A frame here is one message alone.
_SECURED = Size(10, 10, 23)
_UNSECURED = Size(0, 0, 0)


def _secured(wire: int, tag_bytes: int = DEFAULT_TAG_BYTES) -> Size:
    """What the seal adds: per payload (wire format 1), or per packet with the manifest's
    `security: {tag_bytes}` (wire format 2: the tag, K and T on sync packets, C when asking)."""
    if wire != 2:
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
    if wire == 2:                         # H: one byte for ids up to 31, else two
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
        alone = PACKET_ALONE if wire == 2 else FRAME_OVERHEAD
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
    format 1 (wire format 2 says the length once, in the envelope)."""
    n = (bits + 7) // 8
    return n if wire == 2 else n + (1 if n < 24 else 2 if n < 256 else 3)


# --- output -------------------------------------------------------------------------------

def _b(x: int | None) -> str:
    return "unbounded" if x is None else str(x)


def format_analysis(a: Analysis, max_read_length: dict[str, int]) -> str:
    lines = [f"network {a.network}: message sizes (payload and frame bytes; typical / worst) and air time "
             f"at {a.bitrate:g} bit/s"]
    if a.wire_format == 2:
        lines.append("wire format 2: payload = the message in its packet's envelope (header H, no kind "
                     "and id items); frame = that message alone in a packet (+ 4 frame, + 3 P and W); "
                     "messages sharing a packet pay 1 length byte each instead")
    if a.tag_bytes is not None:
        lines.append(f"secure link: one {a.tag_bytes}-byte tag per packet (security tag_bytes; "
                     f"{a.tag_bytes + SYNC_BYTES} on sync packets), counted in frames and budgets of "
                     f"protected entries; forgery odds 2^-{8 * a.tag_bytes} per packet "
                     "(docs/wire-format.md 12.2)")
    for e in a.entries:
        rate = "no rate limit" if e.rate is None else f"{e.rate:g}/s"
        sender = "each client side" if e.sender == "*" else e.sender
        lines += ["", f"{e.kind} {e.name} (id {e.id}, {e.type_name}), sent by {sender}, {rate}"]
        lines.append(f"  {'field':<34}{'encoding':<34}{'packed bits':>12}{'native bytes':>14}")
        for f in e.fields:
            pb = f"{f.bits.typical}" if f.bits.min == f.bits.max else f"{f.bits.min}..{_b(f.bits.max)}"
            nb = f"{f.bytes.typical}" if f.bytes.min == f.bytes.max else f"{f.bytes.min}..{_b(f.bytes.max)}"
            lines.append(f"  {f.path:<34}{f.encoding[:33]:<34}{pb:>12}{nb:>14}")
        mrl = max_read_length.get(e.sender, min(max_read_length.values()))
        lines.append(f"  {'profile':<20}{'payload typ/worst':>20}{'frame typ/worst':>18}{'air time typ':>14}")
        for p in e.profiles:
            mark = " *" if p.configured else ""
            air = air_time(p.frame.typical, a.bitrate, mrl)
            lines.append(f"  {p.label + mark:<20}{f'{p.payload.typical}/{_b(p.payload.max)}':>20}"
                         f"{f'{p.frame.typical}/{_b(p.frame.max)}':>18}{air:>13.3f}s")
    lines += format_control(a.control)
    lines += ["", "link budget (what each side sends, at the configured rates and sizes; * = configured profile)"]
    if a.budgets and a.budgets[0].schema:
        lines.append(f"  (includes {a.budgets[0].schema:.2f} B/s of periodic schema announcements per side)")
    lines.append(f"  capacity: one packet of max_read_length bytes per period, and at most what "
                 f"{a.bitrate:g} bit/s carries (4 bytes per packet are DESERT's)")
    lines.append(f"  {'side':<12}{'capacity B/s':>14}{'limited by':>12}{'typical B/s':>13}{'worst B/s':>12}  verdict")
    for b in a.budgets:
        worst = "unbounded" if b.worst is None else f"{b.worst:.1f}"
        verdict = "fits" if b.fits else "DOES NOT FIT" if b.typical > b.capacity or (
            b.worst is not None and b.worst > b.capacity) else "check warnings"
        lines.append(f"  {b.side:<12}{b.capacity:>14.1f}{b.limited_by:>12}{b.typical:>13.1f}{worst:>12}  {verdict}")
    for w in a.warnings():
        lines.append(f"WARNING: {w}")
    return "\n".join(lines)


def to_json(a: Analysis) -> dict:
    out = asdict(a)
    out["warnings"] = a.warnings()
    return out
