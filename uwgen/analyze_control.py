"""Control traffic in `uwgen analyze`: what discovery and schema announcements cost on the air.

A bridge sends, besides its manifest's traffic, control payloads at start, after every
reconnect of its link and when the far side asks:

- with any entry in profile `rmw_desert`, a discovery request and one beacon per entity it
  announces (wire-format.md section 6.1). Beacons carry rmw_desert's layout byte for byte, so
  uwgen only chooses the node name (the side's) and gid bytes below 24; a beacon longer than
  a packet goes in writes of its own and its last piece is repeated at the start of the next
  write (the echo, uwgen.runtime.link.pacing), which costs its bytes once more;
- with a `schema_id`, its schema announcements (section 10), each sized by the link to leave
  whole in one packet (`uwgen.bridge.schema.whole_payload`): in wire format 2 an envelope of
  its own, in 1 a frame.

Each item says its payload, the bytes written for it, the packets and the air time (DESERT's
4 bytes per packet included), so that a side's start-up cost can be read next to its budget.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from uwgen.manifest.model import RMW_DESERT, Manifest, takes_part
from uwgen.runtime.wire.envelope import HEAD as ENVELOPE_HEAD, v1_message_size
from uwgen.runtime.wire.framing import MAX_PAYLOAD, OVERHEAD as FRAME_OVERHEAD, SHORT_OVERHEAD
from uwgen.runtime.link.packets import envelope_room

DESERT_PACKET_OVERHEAD = 4   # bytes DESERT adds per packet (wire format section 1)
FINGERPRINT_BYTES = 4        # what uwgen announces per id (uwgen.codegen.fingerprint)


@dataclass
class ControlItem:
    what: str
    payload: int        # bytes of the payload (a wire format 1 payload)
    written: int        # bytes written to DESERT for it: frame(s), envelope, echo
    packets: int        # DESERT packets it takes
    air: float          # seconds on the air at the analysis' bit rate


@dataclass
class SideControl:
    side: str
    max_read_length: int
    items: list[ControlItem] = field(default_factory=list)

    @property
    def packets(self) -> int:
        return sum(i.packets for i in self.items)

    @property
    def air(self) -> float:
        return sum(i.air for i in self.items)

    def notes(self) -> list[str]:
        """What a reader should know: beacons that take more than one packet."""
        long = [i for i in self.items if i.what.startswith("beacon") and i.packets > 1]
        if not long:
            return []
        names = ", ".join(i.what.split(" ", 2)[2] for i in long)
        return [f"side {self.side}: {len(long)} of its rmw_desert beacons take more than one "
                f"{self.max_read_length}-byte packet ({names}): rmw_desert's beacon carries the "
                f"names whole, so only a longer max_read_length or shorter topic and type names "
                f"make them fit; their last piece is sent twice (echo), so a lost tail costs "
                f"that beacon only, not the frames after it"]


def air_time(written: int, packets: int, bitrate: float) -> float:
    return (written + DESERT_PACKET_OVERHEAD * packets) * 8 / bitrate


def whole_payload(wire: int, max_read_length: int, protection: int = 0) -> int:
    """The longest payload that leaves whole in one packet (as `Link.whole_payload`)."""
    room = envelope_room(max_read_length) if wire != 1 else max_read_length - FRAME_OVERHEAD
    return max(1, min(MAX_PAYLOAD, room - protection))


def _frame_item(what: str, payload: bytes, mrl: int, bitrate: float) -> ControlItem:
    """A wire format 1 frame, cut into writes of its own when longer than a packet, its last
    piece echoed at the start of the next write."""
    frame = len(payload) + FRAME_OVERHEAD
    packets = max(1, math.ceil(frame / mrl))
    echo = frame - (packets - 1) * mrl if packets > 1 and frame - (packets - 1) * mrl < mrl else 0
    return ControlItem(what, len(payload), frame + echo, packets,
                       air_time(frame + echo, packets, bitrate))


def control_costs(manifest: Manifest, bitrate: float, wire: int,
                  protection: tuple[int, int] = (0, 0)) -> list[SideControl]:
    """Each side's control traffic at start. `protection`: the bytes the secure link adds to a
    signed announcement, typically and at most ((0, 0) when the manifest protects nothing);
    announcements are sized for the most, as the bridge sizes them."""
    typical, most = protection
    out = []
    rmw = manifest.uses_rmw_desert()
    schema_id = getattr(manifest, "schema_id", None)
    entries = (*manifest.topics, *manifest.services, *getattr(manifest, "actions", ()))
    for side in manifest.sides.values():
        mrl = side.link.max_read_length
        # A fleet vehicle announces its own entries only (bridge.schema.attach_schema).
        ids = sorted({e.id for e in entries if takes_part(e, side.name)})
        sc = SideControl(side.name, mrl)
        if rmw:
            from uwgen.interop.beacons import encode_beacon, encode_discovery_request
            from uwgen.interop.discovery import beacons_for
            sc.items.append(_frame_item("discovery request", encode_discovery_request(), mrl, bitrate))
            for b in beacons_for(manifest.network, side.name, manifest.topics, manifest.services):
                sc.items.append(_frame_item(f"beacon {b.entity.name.lower()} {b.topic}",
                                            encode_beacon(b), mrl, bitrate))
        if schema_id is not None:
            from uwgen.bridge.schema import encode_announcements
            size = whole_payload(wire, mrl, most)
            payloads = encode_announcements(schema_id, [(i, bytes(FINGERPRINT_BYTES)) for i in ids],
                                            request=True, max_payload=size)
            for k, p in enumerate(payloads, 1):
                what = f"schema announcement {k}/{len(payloads)}"
                if wire != 1:
                    written = SHORT_OVERHEAD + ENVELOPE_HEAD + v1_message_size(p, last=True) + typical
                    sc.items.append(ControlItem(what, len(p), written, 1, air_time(written, 1, bitrate)))
                else:
                    sc.items.append(_frame_item(what, p + bytes(typical), mrl, bitrate))
                    sc.items[-1].payload = len(p)
        out.append(sc)
    return out


def format_control(sides: list[SideControl]) -> list[str]:
    if not any(s.items for s in sides):
        return []
    lines = ["", "control traffic (what each side sends at start, after each reconnect and when "
                 "asked; air time includes DESERT's 4 bytes per packet)",
             f"  {'side':<12}{'what':<44}{'payload':>8}{'written':>9}{'packets':>9}{'air time':>10}"]
    for s in sides:
        for i in s.items:
            lines.append(f"  {s.side:<12}{i.what[:43]:<44}{i.payload:>8}{i.written:>9}{i.packets:>9}"
                         f"{i.air:>9.3f}s")
        if s.items:
            lines.append(f"  {s.side:<12}{'total':<44}{'':>8}{sum(i.written for i in s.items):>9}"
                         f"{s.packets:>9}{s.air:>9.3f}s")
    for s in sides:
        lines += [f"note: {n}" for n in s.notes()]
    return lines
