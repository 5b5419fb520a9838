"""One or both sides' recordings, matched across the link: the run's table (as the demo
prints it, uwgen.fieldkit.table), packets lost on the way, duplicates, and the series the
plots draw.

Matching. A message is the same on both sides when the CRC-32 of the payload it crossed
the link as is (the recorder stores it as the MCAP message's `sequence`): its latency runs
from its publication (the sending side's publish_time, the publisher's source timestamp)
to the receiving bridge's publication. A message the receiving bridge published while no
subscriber listened (`/uwgen/unheard`) is not delivered. A payload sent more than once (a vehicle standing
still publishes the same pose again and again) is ambiguous and left out of the latencies,
as the demo leaves out such keys; one received more often than it was sent is a duplicate.
A service's round trip runs from the local call to the response the calling side's bridge
returned (`/uwgen/calls`). A packet is the same on both sides when its bytes are: a packet one side wrote that the
other never read was lost on the way. Counts (taken, policy, on link, lost) are the
bridges' own, from the last status each recorded (the final one unless cut short).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from uwgen.fieldkit.reader import Recording, clock
from uwgen.fieldkit.table import Row, ServiceRow, format_tables, latencies_by_key, ms, topic_row
from uwgen.runtime.link.pacing import PACKET_HEADER
from uwgen.runtime.link.scheduler import DROP_REASONS
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD


@dataclass
class Side:
    name: str
    sent: list[tuple[float, int, bool | None]] = field(default_factory=list)  # (t, air bytes, arrived)
    received: Counter = field(default_factory=Counter)     # outcome kind -> packets
    dropped: Counter = field(default_factory=Counter)      # reason -> packets dropped on receive

    @property
    def air_bytes(self) -> int:
        return sum(b for _t, b, _a in self.sent)

    @property
    def lost(self) -> int | None:
        known = [a for _t, _b, a in self.sent if a is not None]
        return len(known) - sum(known) if known else None


@dataclass
class Summary:
    recordings: list[Recording]
    topics: list[Row]
    services: list[ServiceRow]
    sides: dict[str, Side]
    duplicates: dict[str, int]
    latency_series: dict[str, list[tuple[float, float]]]    # topic -> (arrival, latency)
    policy: dict[str, Counter]                               # side -> dropped by policy, by reason

    @property
    def both(self) -> bool:
        return len(self.recordings) > 1


def summarise(recordings: list[Recording]) -> Summary:
    by_side = {r.side: r for r in recordings}
    rows, series, duplicates = [], {}, {}
    names = sorted({t for r in recordings for t in r.topics})
    for name in names:
        senders = [r for r in recordings if r.topics.get(name) == "out"]
        receivers = [r for r in recordings if r.topics.get(name) == "in"]
        sender = senders[0] if senders else None
        receiver = receivers[0] if receivers else None
        row = _row(name, sender, receiver)
        if sender is not None and receiver is not None:
            sent = [(m.crc, m.published) for m in sender.messages.get(name, [])]
            got = [(m.crc, m.t) for m in receiver.messages.get(name, []) if m.heard]
            row.latencies = latencies_by_key(sent, got)
            once = {k for k, n in Counter(k for k, _t in sent).items() if n == 1}
            seen = Counter(k for k, _t in got if k in once)
            duplicates[name] = sum(n - 1 for n in seen.values() if n > 1)
            first = dict(sent)
            series[name] = [(t, t - first[k]) for k, t in got if k in once and first[k] <= t]
        rows.append(row)
    return Summary(recordings, rows, _services(recordings), _packets(by_side), duplicates, series,
                   {r.side: _policy(r) for r in recordings})


def _row(name: str, sender: Recording | None, receiver: Recording | None) -> Row:
    direction = f"{sender.side if sender else '?'} → {receiver.side if receiver else '?'}"
    if sender is not None and receiver is not None:
        row = topic_row(name, direction, sender.status, receiver.status)
    else:
        row = Row(name, direction)
        acc = ((sender or receiver).status.get("topics", {}).get(name) or {}).get("accounting") or {}
        if sender is not None and "taken" in acc:
            row.taken, row.sub_dropped = acc["taken"], acc["dropped_by_subscription"]
            row.policy, row.on_link = sum(acc["dropped_by_policy"].values()), acc["sent"]
    if sender is not None:
        acc = (sender.status.get("topics", {}).get(name) or {}).get("accounting") or {}
        row.published = acc.get("published", len(sender.messages.get(name, [])))
    if receiver is not None:
        row.delivered = sum(m.heard for m in receiver.messages.get(name, []))
    return row


def _services(recordings: list[Recording]) -> list[ServiceRow]:
    rows: dict[str, ServiceRow] = {}
    for rec in recordings:
        for name, s in (rec.status.get("services") or {}).items():
            row = rows.setdefault(name, ServiceRow(name))
            if s.get("role") == "client":
                row.calls, row.ok = s.get("local_calls", 0), s.get("responses", 0)
                row.failed = row.calls - row.ok
            link = s.get("link") or {}
            row.policy += sum(int(link.get(r, 0)) for r in DROP_REASONS)
            exact = link.get("on_link")
            if isinstance(exact, dict) and "lost_on_link" in exact:
                row.lost_on_link = (row.lost_on_link or 0) + int(exact["lost_on_link"])
        for call in rec.calls:
            if call.get("ok") and call.get("service") in rows:
                rows[call["service"]].rtts.append(float(call["end"]) - float(call["start"]))
    return [rows[n] for n in sorted(rows)]


def _packets(by_side: dict[str, Recording]) -> dict[str, Side]:
    sides = {}
    for name, rec in by_side.items():
        others = [r for n, r in by_side.items() if n != name]
        heard = Counter(p.data for r in others for p in r.packets if p.dir == "rx")
        side = sides[name] = Side(name)
        for p in rec.packets:
            if p.dir == "tx":
                arrived = None
                if others:
                    arrived = heard[p.data] > 0
                    if arrived:
                        heard[p.data] -= 1
                side.sent.append((p.t, p.size + FRAME_OVERHEAD + PACKET_HEADER, arrived))
            else:
                kind, _, reason = p.outcome.partition(" ")
                side.received[kind] += 1
                if kind == "dropped":
                    side.dropped[reason] += 1
    return sides


def _policy(rec: Recording) -> Counter:
    out: Counter = Counter()
    for name, entry in (rec.status.get("topics") or {}).items():
        for reason, n in ((entry.get("accounting") or {}).get("dropped_by_policy") or {}).items():
            out[reason] += int(n)
    return out


def format_summary(s: Summary) -> str:
    lines = []
    for rec in s.recordings:
        span = rec.span
        side = s.sides.get(rec.side)
        lines.append(f"{rec.network}/{rec.side}: {', '.join(str(f) for f in rec.files)}; "
                     + (f"{clock(span[0])} to {clock(span[1])} ({span[1] - span[0]:.1f} s)" if span
                        else "nothing recorded")
                     + f"; {rec.max_read_length} B every {rec.period:g} s")
        if side is not None:
            lost = side.lost
            lines.append(f"  sent {len(side.sent)} packets ({side.air_bytes} B on the air: frames and "
                         f"DESERT's {PACKET_HEADER}-byte header included)"
                         + (f", {lost} lost on the way" if lost is not None else "")
                         + f"; received {sum(side.received.values())}"
                         + (f" ({', '.join(f'{k} {n}' for k, n in sorted(side.received.items()))})"
                            if side.received else "")
                         + (f"; dropped on receive: {', '.join(f'{k} {n}' for k, n in sorted(side.dropped.items()))}"
                            if side.dropped else ""))
        for end in rec.ends:
            lines.append(f"  {end}")
        if not rec.statuses:
            lines.append("  no status recorded: counts from the bridge are missing")
        elif rec.ends:
            lines.append(f"  counts are the bridge's last status before the end, at {clock(rec.statuses[-1][0])}")
    if not s.both:
        lines.append("one side only: lost and latencies need both sides' recordings")
    lines.append("")
    lines += format_tables(s.topics, s.services)
    if any(r.ok and not r.rtts for r in s.services):
        lines.append("  round trip: from the calling side's recording (not given here)")
    dups = {k: v for k, v in s.duplicates.items() if v}
    lines.append("duplicates delivered: " + (", ".join(f"{k} {v}" for k, v in dups.items()) if dups else "none"))
    for name, pts in s.latency_series.items():
        if pts:
            worst = max(pts, key=lambda p: p[1])
            lines.append(f"{name}: slowest message {ms(worst[1])}, delivered at {clock(worst[0])}")
    return "\n".join(lines)
