"""What the manifest's MAC (`mac:`, uwgen.manifest.mac) leaves each side, for `uwgen analyze`.

- capacity: mode none keeps the link's (a packet per period, the bit rate); tdma gives a side
  the packets its slot drains per frame (uwgen.runtime.link.mac.tdma_capacity; a side's
  slot is its weight's share of the frame); turns gives it its turn's packets per round of
  turns; `mac_shares` says each side's slot or turn in one line;
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
        share = tdma_capacity(mac, link, side.name) * link.max_read_length / mac.frame
        return (share, "tdma slot") if share < capacity else (capacity, limit)
    if mac.mode == "turns":
        cycle = turn_cycle(manifest)
        share = mac.turn_packets(side.name) * link.max_read_length / cycle
        return (share, "turns") if share < capacity else (capacity, limit)
    return capacity, limit


def mac_shares(manifest: Manifest) -> list[str]:
    """Each side's share of the channel under the MAC, a line per side (none: nothing)."""
    from uwgen.runtime.link.slot_timing import send_window, tdma_capacity

    mac = manifest.mac
    if mac.mode == "tdma":
        out = [f"mac tdma: a {mac.frame:g} s frame, guard {mac.guard:g} s, max_packet_per_slot "
               f"{mac.max_packet_per_slot}, queue_size {mac.queue_size}; per side:"]
        for name in mac.slots:
            side = manifest.sides[name]
            start, length = mac.slot_start(name), mac.slot_length(name)
            weight = f", weight {mac.weight(name)}" if mac.weights else ""
            window = send_window(mac, side.link, name)
            sends = (f", packets start by {window:.3f} s to end before the next slot"
                     if window < length - mac.guard - 1e-9 else "")
            out.append(f"  {name:<12} slot {start:.3f}-{start + length:.3f} s{weight}, ON "
                       f"{length - mac.guard:.3f} s{sends}: {tdma_capacity(mac, side.link, name)} "
                       "packets a frame")
        return out
    if mac.mode == "turns":
        cycle = turn_cycle(manifest)
        out = [f"mac turns: leader {mac.leader}, a round of turns about {cycle:.2f} s; per side:"]
        out += [f"  {name:<12} {mac.turn_packets(name)} packets a turn"
                for name in manifest.sides]
        return out
    return []


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
        from uwgen.runtime.link.mac import tdma_capacity
        from uwgen.runtime.link.slot_timing import blind_frames, blind_safe, overrun
        shortest = min(mac.slots, key=mac.slot_length)
        for name in (s for s in mac.slots if mac.weight(s) > mac.weight(shortest)):
            link = manifest.sides[name].link
            if tdma_capacity(mac, link, name) <= tdma_capacity(mac, link, shortest):
                out.append(f"mac tdma: side {name}'s longer slot (weight {mac.weight(name)}) drains "
                           f"no more than a weight-{mac.weight(shortest)} one: max_packet_per_slot "
                           f"{mac.max_packet_per_slot}, queue_size {mac.queue_size} or the period "
                           "caps it; raise them")
        if not blind_safe(mac, longest):
            out.append(f"mac tdma: guard {mac.guard:g} s is shorter than a {longest.max_read_length}-byte "
                       f"packet's air time plus the {mac.range:g} m range "
                       f"({overrun(mac, longest):.3f} s): a packet "
                       "DESERT starts at the end of a slot's ON window runs into the next slot, so "
                       "a side writes only what starts early enough, and until it has heard the "
                       f"frame's phase it listens, then writes a packet every "
                       f"{blind_frames(mac, longest)} frames")
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
