"""The table of a run, per topic and service: what the demo report and `uwgen log` print.

Columns, per topic (from the publishing side to the other):
  published  messages the application published
  taken      messages the sending bridge received from its local graph
  sub drop   messages its local subscription reported lost before the bridge took them
  on link    messages the sending link put on the wire (whole or in fragments)
  policy     messages dropped by policy (superseded, overflow, expired, too large, encode
             errors, echo guard), by reason in the bridges' status (`accounting`)
  lost       messages put on the wire that the far bridge never received (packet loss);
             (seen N): of those, N the link knows were lost (named by acknowledgements,
             or fragmented messages that never completed), never more than lost
  delivered  messages the far application received
  latency    from publication to delivery (median and 95th percentile), matched per message
So `taken = on link + policy + still queued`, and `on link = received by the far bridge + lost`
(uwgen.runtime.delivery.ledger, pure accounting); a topic whose bridge counters do not add up is named
under the table. The counts come from the two bridges' final status (`topic_row`); the
demo fills published, delivered and latencies from its applications' records, `uwgen log`
from the bridges' recordings (uwgen.fieldkit.summary).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import median
from typing import Iterable

from uwgen.runtime.delivery import ledger
from uwgen.runtime.link.scheduler import DROP_REASONS


def percentile(values: list[float], q: float) -> float | None:
    """Linear-interpolated percentile (q in 0..100), None for no values."""
    if not values:
        return None
    s = sorted(values)
    pos = (len(s) - 1) * q / 100.0
    lo, hi = math.floor(pos), math.ceil(pos)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


@dataclass
class Row:
    name: str
    direction: str
    published: int = 0
    taken: int = 0
    on_link: int = 0
    policy: int = 0
    queued: int = 0
    lost: int = 0
    lost_seen: int = 0
    sub_dropped: int = 0
    delivered: int = 0
    imbalances: list[str] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)

    @property
    def p50(self) -> float | None:
        return median(self.latencies) if self.latencies else None

    @property
    def p95(self) -> float | None:
        return percentile(self.latencies, 95)


@dataclass
class ServiceRow:
    name: str
    calls: int = 0
    ok: int = 0
    failed: int = 0
    policy: int = 0
    lost_on_link: int | None = None   # copies the sending links' acks name lost (wire format 2)
    rtts: list[float] = field(default_factory=list)


def latencies_by_key(sent: Iterable[tuple[object, float]], received: Iterable[tuple[object, float]]) -> list[float]:
    """For each received (key, t), the delay since the send of the same key. Keys sent more
    than once (a vehicle standing still publishes the same pose again and again) are
    ambiguous and left out rather than guessed."""
    by_key: dict[object, list[float]] = {}
    for key, t in sent:
        by_key.setdefault(key, []).append(t)
    out = []
    for key, t in received:
        times = by_key.get(key, ())
        if len(times) == 1 and times[0] <= t:
            out.append(t - times[0])
    return out



def topic_row(name: str, direction: str, sender: dict, receiver: dict) -> Row:
    """The counts of one topic from its sending and receiving bridges' status dicts."""
    row = Row(name, direction)
    out = sender.get("topics", {}).get(name, {})
    inc = receiver.get("topics", {}).get(name, {})
    link = out.get("link", {}) or {}
    if "accounting" in out and "accounting" in inc:
        acc, rx = out["accounting"], inc["accounting"]
        row.taken, row.sub_dropped = acc["taken"], acc["dropped_by_subscription"]
        row.policy, row.queued = sum(acc["dropped_by_policy"].values()), acc["queued"]
        flow = ledger.across(acc, rx)
        row.on_link, row.lost, row.lost_seen = flow["sent"], flow["lost"], flow["lost_on_link"]
        exact = link.get("on_link")
        if isinstance(exact, dict) and "lost_on_link" in exact and not link.get("fragments_sent"):
            # Named by acks (wire-format 15.7), in copies: messages only where none went in
            # fragments (then the receiver's count of incomplete messages above stands). Never
            # more than were lost: a copy the acks name missing may still have arrived.
            row.lost_seen = min(int(exact["lost_on_link"]), row.lost)
        row.imbalances = ledger.imbalances(acc) + ledger.imbalances(rx)
        return row
    row.taken = out.get("taken", 0)
    row.policy = sum(int(link.get(r, 0)) for r in DROP_REASONS)
    row.queued = int(link.get("queued", 0))
    row.on_link = max(0, int(link.get("offered", 0)) - row.policy - row.queued)
    row.lost = max(0, row.on_link - inc.get("received", 0))
    return row



def ms(x: float | None) -> str:
    return "-" if x is None else f"{x * 1000:.0f} ms"



COLUMNS = """\
  taken: by the sending bridge from its local graph; sub drop: messages the sending bridge's
  subscription lost before it took them (its ROS queue overflowed); on link: put on the wire;
  policy: dropped by the topic's link policy (superseded by a newer one, rate, ttl, overflow);
  lost (seen): put on the link, never received by the far bridge; (seen) of those, how many
  the link knows were lost: on wire format 2 those the far side's acknowledgements name
  missing (wire-format 15.7), for a fragmented topic those of which some fragments arrived"""



def format_tables(topics: list[Row], services: list[ServiceRow]) -> list[str]:
    """The topic table, its column notes, then the service table, as lines."""
    lines: list[str] = []
    head = (f"{'topic':<20} {'direction':<18} {'published':>9} {'taken':>6} {'sub drop':>8} "
            f"{'on link':>7} {'policy':>6} {'lost (seen)':>11} {'delivered':>9} {'latency p50':>11} {'p95':>8}")
    lines += [head, "-" * len(head)]
    for r in topics:
        lost = f"{r.lost} ({r.lost_seen})" if r.lost_seen else str(r.lost)
        lines.append(f"{r.name:<20} {r.direction:<18} {r.published:>9} {r.taken:>6} {r.sub_dropped:>8} "
                     f"{r.on_link:>7} {r.policy:>6} {lost:>11} {r.delivered:>9} {ms(r.p50):>11} {ms(r.p95):>8}")
    for r in topics:
        for problem in r.imbalances:
            lines.append(f"  {r.name}: counters do not add up: {problem}")
    lines += COLUMNS.splitlines()
    lines.append("")
    shead = (f"{'service':<28} {'calls':>5} {'ok':>4} {'failed':>6} {'policy':>6} "
             f"{'lost on link':>12} {'round trip p50':>14} {'p95':>8}")
    lines += [shead, "-" * len(shead)]
    for s in services:
        lost = "-" if s.lost_on_link is None else str(s.lost_on_link)
        lines.append(f"{s.name:<28} {s.calls:>5} {s.ok:>4} {s.failed:>6} {s.policy:>6} {lost:>12} "
                     f"{ms(median(s.rtts) if s.rtts else None):>14} {ms(percentile(s.rtts, 95)):>8}")
    lines.append("  lost on link: requests and responses (copies included) the far side's "
                 "acknowledgements name missing; re-sent by the bridges (wire-format 15.6)")
    return lines
