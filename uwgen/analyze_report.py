"""The text and JSON forms of `uwgen analyze`'s result (uwgen.analyze.Analysis)."""
from __future__ import annotations

from dataclasses import asdict

from uwgen.analyze import Analysis, air_time
from uwgen.analyze_control import format_control
from uwgen.security.packet_seal import SYNC_BYTES

def _b(x: int | None) -> str:
    return "unbounded" if x is None else str(x)


def format_analysis(a: Analysis, max_read_length: dict[str, int]) -> str:
    lines = [f"network {a.network}: message sizes (payload and frame bytes; typical / worst) and air time "
             f"at {a.bitrate:g} bit/s"]
    if a.wire_format != 1:
        lines.append(f"wire format {a.wire_format}: payload = the message in its packet's envelope (header H, no kind "
                     "and id items); frame = that message alone in a packet (+ 1 short frame, + 3 P and W); "
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
    lines += [f"  {line}" for line in a.mac_shares]
    for w in a.warnings():
        lines.append(f"WARNING: {w}")
    return "\n".join(lines)


def to_json(a: Analysis) -> dict:
    out = asdict(a)
    out["warnings"] = a.warnings()
    return out
