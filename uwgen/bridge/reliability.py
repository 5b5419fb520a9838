"""Which entries of a side's plan the link makes reliable, and how old each may arrive
(docs/wire-format.md sections 15.4-15.6), turned into the link's reliability hooks.

- reliable (re-sent by the link, delivered once): topics with `reliability: reliable`;
- max age (age item, T, `stale` at the receiver): a topic's `ttl`; a service's `ttl`, else
  its `timeout`; an action's `ttl`, else its `accept_timeout`. Services and actions are
  re-sent by the bridge (section 15.6), never by the link as well.

Both sides compute the same from the same manifest. Wire format 1 links (a manifest with an
rmw_desert entry) have none of this: `reliability_for` gives None.
"""
from __future__ import annotations

from typing import Any, Callable

from uwgen.bridge.plan import BridgePlan
from uwgen.manifest.model import LinkConfig
from uwgen.runtime.clock import WALL_CLOCK, Clock
from uwgen.runtime.delivery.epoch import new_epoch
from uwgen.runtime.delivery.reliability import Reliability


def reliable_topics(plan: BridgePlan) -> dict[int, float | None]:
    """Topic id -> its ttl (the re-send deadline from publication), for reliable topics."""
    return {t.id: t.policy.ttl for t in plan.topics if getattr(t.policy, "reliable", False)}


def max_ages(plan: BridgePlan) -> dict[int, float]:
    """Wire id -> the most a message of it may have aged when it arrives (section 15.5)."""
    ages: dict[int, float] = {t.id: t.policy.ttl for t in plan.topics if t.policy.ttl is not None}
    for s in plan.services:
        limit = s.policy.ttl if s.policy.ttl is not None else getattr(s, "timeout", None)
        if limit is not None:
            ages[s.id] = float(limit)
    for a in (*plan.offered_actions, *plan.served_actions):
        limit = a.policy.ttl if a.policy.ttl is not None else getattr(a, "accept_timeout", None)
        if limit is not None:
            ages[a.id] = float(limit)
    return ages


def command_keys(plan: BridgePlan) -> frozenset[int]:
    """The link channel keys of this side's services and actions (requests, responses,
    goals, answers, results; an action's feedback is on its own key, not among them)."""
    return frozenset(e.id for e in (*plan.services, *plan.offered_actions, *plan.served_actions))


def destinations(plan: BridgePlan, senders: dict[str, int]) -> dict[int, frozenset[int]] | None:
    """Wire id -> the sender ids of the peers this side's messages of it are for, when
    some entry names its peers (a fleet: each vehicle's entries are between it and the
    surface); None otherwise (every packet is for every other side). An entry of the whole
    network is for every side this side shares a fleet entry with."""
    entries = [e for e in (*plan.topics, *plan.services, *plan.offered_actions, *plan.served_actions)]
    if not any(getattr(e, "peers", ()) for e in entries):
        return None
    me = plan.side
    ids = lambda sides: frozenset(senders[s] for s in sides if s != me and s in senders)  # noqa: E731
    shared = ids({p for e in entries for p in getattr(e, "peers", ())})
    return {e.id: ids(e.peers) if getattr(e, "peers", ()) else shared for e in entries}


class _Wall:
    """A Clock reading a `() -> seconds` function (the bridge's wall time, injectable)."""

    def __init__(self, read: Callable[[], float]):
        self.now = read


def reliability_for(plan: BridgePlan, link: LinkConfig,
                    wall: Clock | Callable[[], float] = WALL_CLOCK, *,
                    other_overhead: int = 0, turn_gap: float = 0.0,
                    settled_by: Callable[[int, float], float | None] | None = None,
                    unheard: Callable[[int], float | None] | None = None,
                    own_span: float = 0.0, twice: bool = False) -> Reliability | None:
    """The link's reliability of this side (None on wire format 1). `wall`: the wall clock
    T is stamped with and checked against (a Clock, or a function giving seconds);
    `other_overhead`: what the hooks joined with it (the per-packet seal, the MAC) add to a
    packet; `turn_gap`: the MAC's longest wait for the peer's turn, `settled_by` what a
    peer's answer covers of this side's packets and `unheard` when a peer's turn went unheard,
    `own_span` how long its own turn or slot
    lasts (uwgen.runtime.link.mac): its services' and actions' messages get a copy in spare
    room within it (uwgen.runtime.delivery.echoes); `twice`: a report telling a loss rides
    the next packet too (the MAC's `reports_twice`: under turns, the leader)."""
    if plan.wire_format != 2:
        return None
    clock = wall if hasattr(wall, "now") else _Wall(wall)
    out = Reliability(plan.sender_id, period=link.period, reliable=reliable_topics(plan),
                      max_ages=max_ages(plan), wall=clock, name=plan.side,
                      max_read_length=link.max_read_length, other_overhead=other_overhead,
                      turn_gap=turn_gap, settled_by=settled_by, unheard=unheard,
                      commands=command_keys(plan), own_span=own_span,
                      destinations=destinations(plan, plan.side_ids),
                      peer_names={i: s for s, i in plan.side_ids.items() if s != plan.side},
                      # K on an unsealed link is this side's; a sealed link's is the seal's
                      epoch_source=new_epoch if plan.security is None else None,
                      # probes at start, so commands are judged with a measured offset
                      clock_exchange=True)
    out.acks.twice = twice
    return out


def wire_commands(w: Any, reliability: Reliability) -> None:
    """What the bridge's commands get from the link's reliability (docs/wire-format.md
    section 15.6): a copy in their turn when sent again (`repeat`), their fates as the peer's
    reports tell them, the reports' word on a result's arrival, and when a command that came
    began on its caller's side (its age item: `Wiring.began`)."""
    w.repeat, reliability.on_fate, w.reports = reliability.repeat, w.fates.told, True
    w.began_at = reliability.judge.began


def link_ledger(link_stats: Any) -> dict[int, dict]:
    """The link's per-entry ledger from its stats (keys as ints; JSON may have made them text)."""
    ledger = link_stats.get("ledger") if isinstance(link_stats, dict) else None
    return {int(k): v for k, v in (ledger or {}).items()}


def farewell(reliability: Reliability | None, link: Any, period: float) -> None:
    """The last acknowledgements before the link closes (SIGINT/SIGTERM, close()): one packet
    reporting every peer's packets, so their ledgers close; bounded by 2 periods plus a
    second (wall clock: shutdown ends whatever an injected clock does)."""
    import threading
    import time
    try:
        if reliability is None or not link.stats().get("connected") or not reliability.farewell():
            return
    except Exception:
        return
    deadline = time.monotonic() + 2 * period + 1.0
    waiter = threading.Event()
    wake = getattr(getattr(link, "connection", None), "wake", None)
    if wake is not None:
        wake()
    while reliability.farewell_pending and time.monotonic() < deadline:
        waiter.wait(0.01)
    if not reliability.farewell_pending:
        waiter.wait(period)           # DESERT reads the last write before the socket closes
