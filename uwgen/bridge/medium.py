"""The bridge's side of the MAC (docs/seams.md section 7; uwgen.runtime.link.mac).

`BridgeNode` builds its side's `Mac` with `uwgen.runtime.link.mac.mac_for`; here is what
goes with it: the link's keyword (`link_mac`: the `Mac` a link needs besides mode none),
the least round trip a command can take under the MAC (`mac_round_trip`: the floor of the
commands' retransmission timers, `uwgen.runtime.delivery.reliable.command_rtt`), and the
deadlines that cannot fit one round trip under it, said at start (`warn_deadlines`), as
`uwgen analyze` says them.
"""
from __future__ import annotations

from typing import Any

from uwgen.bridge.plan import BridgePlan


def link_mac(mac: Any) -> dict:
    """The Link's `mac=` keyword (none for mode none: a link factory need not know it)."""
    return {"mac": mac} if mac.mode != "none" else {}


def mac_round_trip(plan: BridgePlan, link: Any) -> float | None:
    """The least a request and its answer can take under the plan's MAC: across the range
    and on the air both ways, and a slot under TDMA (None: mode none, where the commands'
    timers keep their default)."""
    from uwgen.manifest.mac import air_time
    mac = plan.mac
    if mac is None or mac.mode == "none":
        return None
    least = 2 * (mac.delay + air_time(link.max_read_length, mac.bitrate))
    return least + (mac.slot if mac.mode == "tdma" else 0.0)


def deadline_problems(plan: BridgePlan, link: Any) -> list[str]:
    """Deadlines of this side's calls and goals that cannot fit one round trip under the MAC
    (uwgen.manifest.mac.round_trip): said at start, as `uwgen analyze` says them."""
    from uwgen.manifest.mac import round_trip
    from uwgen.manifest.model import MacConfig
    mac = plan.mac or MacConfig()
    rt = round_trip(mac, link.period, link.max_read_length, list(plan.side_ids))
    out = []
    for entry, key in ((s, "timeout") for s in plan.called_services):
        limit = getattr(entry, key, None)
        if limit is not None and limit < rt:
            out.append(f"service {entry.name}: its timeout {limit:g} s cannot fit one round trip "
                       f"under mac {mac.mode} (about {rt:.1f} s): its calls will time out")
    for entry in plan.offered_actions:
        limit = getattr(entry, "accept_timeout", None)
        if limit is not None and limit < rt:
            out.append(f"action {entry.name}: its accept_timeout {limit:g} s cannot fit one round "
                       f"trip under mac {mac.mode} (about {rt:.1f} s): its goals will be rejected")
    return out


def warn_deadlines(log: Any, plan: BridgePlan, link: Any) -> None:
    for problem in deadline_problems(plan, link):
        log.warning(problem)
