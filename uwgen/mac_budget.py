"""What the manifest's MAC (`mac:`, uwgen.manifest.mac) leaves each side, for `uwgen analyze`.

- capacity: mode none keeps the link's (a packet per period, the bit rate); tdma gives a side
  the packets one slot drains per frame (uwgen.runtime.link.mac.tdma_capacity); turns gives
  it its turn's packets per round of turns;
- warnings: a TDMA guard a packet starting at the end of the ON window overruns (it runs into
  the next side's slot: DESERT does not check that it fits), and every deadline (a service's
  timeout, an action's accept_timeout, a reliable topic's ttl) that cannot fit one round trip
  under the MAC (uwgen.manifest.mac.round_trip).
"""
from __future__ import annotations

from uwgen.manifest.mac import air_time, round_trip
from uwgen.manifest.model import Manifest, Side


def capacity_under_mac(manifest: Manifest, side: Side, capacity: float, limit: str) -> tuple[float, str]:
    """(payload bytes per second `side` may send under the MAC, what limits it)."""
    from uwgen.runtime.link.mac import tdma_capacity

    mac = manifest.mac
    link = side.link
    if mac.mode == "tdma":
        share = tdma_capacity(mac, link) * link.max_read_length / mac.frame
        return (share, "tdma slot") if share < capacity else (capacity, limit)
    if mac.mode == "turns":
        cycle = turn_cycle(manifest)
        share = mac.turn_packets(side.name) * link.max_read_length / cycle
        return (share, "turns") if share < capacity else (capacity, limit)
    return capacity, limit


def turn_cycle(manifest: Manifest) -> float:
    """Seconds of one round of turns with every side's turn full."""
    mac = manifest.mac
    first = next(iter(manifest.sides.values())).link
    return round_trip(mac, first.period, first.max_read_length, list(manifest.sides)) - 2 * (
        first.period + air_time(first.max_read_length, mac.bitrate) + mac.delay)


def mac_warnings(manifest: Manifest) -> list[str]:
    mac = manifest.mac
    out: list[str] = []
    if mac.mode == "none":
        if len(manifest.sides) > 1:
            out.append("mac mode none: the sides write whenever their period allows and DESERT's "
                       "MAC decides; packets of two sides can collide (mac: {mode: turns} needs no "
                       "change in DESERT)")
        return out
    links = {s.name: s.link for s in manifest.sides.values()}
    longest = max(links.values(), key=lambda link: link.max_read_length)
    if mac.mode == "tdma":
        overrun = air_time(longest.max_read_length, mac.bitrate) + mac.delay
        if mac.guard < overrun:
            out.append(f"mac tdma: guard {mac.guard:g} s is shorter than a {longest.max_read_length}-byte "
                       f"packet's air time plus the {mac.range:g} m range ({overrun:.3f} s): a packet "
                       "DESERT starts at the end of a slot's ON window runs into the next slot")
    rt = round_trip(mac, longest.period, longest.max_read_length, list(manifest.sides))
    deadlines = [(f"service {s.name}", "timeout", s.timeout) for s in manifest.services]
    deadlines += [(f"action {a.name}", "accept_timeout", a.accept_timeout)
                  for a in getattr(manifest, "actions", ())]
    deadlines += [(f"topic {t.name}", "ttl", t.policy.ttl) for t in manifest.topics
                  if t.policy.reliable and t.policy.ttl is not None]
    for what, key, limit in deadlines:
        if limit is not None and limit < rt:
            out.append(f"{what}: its {key} {limit:g} s cannot fit one round trip under mac "
                       f"{mac.mode} (about {rt:.1f} s)")
    return out
