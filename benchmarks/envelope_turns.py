"""Table 0's second part: the demo's mix as the demo runs it, under the manifest's MAC.

The demo manifest (msg_samples/uwgen.yaml) sets `mac: {mode: turns, ...}`: the surface grants
turns, each side sends at most its manifest's packets a turn (docs/seams.md section 7,
uwgen.runtime.link.mac). Each side's Link then gets `mac_for`'s TurnMac, and its reliability
the MAC's overhead, turn gap and `settled_by`, as `uwgen.bridge.node` joins them. The packets
go through the emulator's sans-IO core (uwgen.emulator.core: the manifest's range and
bitrate, stock CSMA-ALOHA underneath, no loss model) on simulated time, as
`uwgen.emulator.duplex` drives it: a side writes only when its pacer and its MAC allow.
Messages then share packets (their heads are paid once a packet) and the MAC adds its C
items (grant, notice, end of turn).
"""
from __future__ import annotations

from envelope_parts import DESERT_HEADER, PARTS

GOALS = {"unsecured": 15.0, "secured": 21.0}
NAMES = {4: "cmd_vel", 5: "pose", 6: "battery", 7: "log", 20: "teleport"}


def mac_kw(pair, plan, side: str, config, seal_overhead: int) -> dict:
    """`side`'s Mac under the plan's (the demo manifest's) `mac:` section, kept in
    `pair.macs`; the keywords reliability_for takes from it (as uwgen.bridge.node passes)."""
    from uwgen.runtime.link.mac import mac_for
    mac = pair.macs[side] = mac_for(plan.mac, side, plan.side_ids, config, plan.wire_format)
    pair.mac_config = plan.mac
    return {"other_overhead": seal_overhead + mac.overhead, "turn_gap": mac.turn_gap(),
            "settled_by": mac.settled_by}


def scenario(mac, config):
    """Two DESERT nodes the manifest's range apart, its link settings, its MAC's bitrate."""
    from uwgen.emulator.from_manifest import with_mac
    from uwgen.emulator.scenario import NodeSpec, Scenario
    return with_mac(Scenario(nodes=[NodeSpec("surface", position=(0.0, 0.0, 0.0), dest="vehicle"),
                                    NodeSpec("vehicle", position=(mac.range, 0.0, 0.0), dest="surface")],
                             period=config.period, max_read_length=config.max_read_length), mac)


def run_on_core(pair, seconds: float, before_write, config) -> None:
    """Play both sides' writes through the emulator's core until `seconds` (DuplexSim's
    loop, with the pair's packet counting): a side writes when its MAC allows it."""
    from uwgen.emulator.core import EmulatorCore
    core = pair.core = EmulatorCore(scenario(pair.mac_config, config))
    links = {link.name: link for link in (pair.sender, pair.receiver)}
    for name in links:
        core.client_attached(name, 0.0)
    t, step = 0.0, config.period / 8
    while t <= seconds:
        pair.clock.set(t)
        if before_write is not None:
            before_write(t)
        for name, link in links.items():
            conn = link.connection
            if link.mac.next_write_at(t) > t:          # not this side's turn
                continue
            batch = conn.outbox.take(t, conn._pull, conn._fit)
            if batch:
                conn.outbox.sent(t)
                link.mac.wrote(t, len(batch))
                core.client_data(name, t, batch)
                pair.batches.append(batch)
                pair.packets += 1
                pair.written += len(batch)
                pair.air += len(batch) + DESERT_HEADER
        for d in core.advance(t):
            conn = links[d.node].connection
            conn._deliver(conn.decoder.feed(d.data))
        for link in links.values():
            link._tick(t)
        t = round(t + step, 9)


def outcome(pair) -> dict:
    """Delivered messages per id (both ways), refusals (reliability's stale, the seal's
    stale), the MAC's counters and the emulator's losses."""
    per_id: dict[int, int] = {}
    for p in pair.delivered + pair.returned:
        ident = p[1] if p[1] < 24 else p[2]
        if ident != 249:
            per_id[ident] = per_id.get(ident, 0) + 1
    out = {"per_id": per_id,
           "stale": sum(r.counters.as_dict().get("stale", 0) for r in pair.rel.values()),
           "seal_stale": sum(s.stats().get("stale", 0) for s in pair.seals.values())}
    if pair.macs:
        stats = {side: mac.stats() for side, mac in pair.macs.items()}
        out["mac"] = {k: sum(s.get(k, 0) for s in stats.values())
                      for k in ("turns", "grants_sent", "ends_heard", "missed", "dropped_turns",
                                "turns_from_notice", "recovered")}
        lost = [pair.core.counters(n) for n in pair.macs]
        out["lost"] = sum(v for c in lost for k, v in c.items() if k.startswith("lost_"))
    return out


def merge(into: dict, more: dict) -> None:
    for k, v in more.items():
        if isinstance(v, dict):
            merge(into.setdefault(k, {}), v)
        else:
            into[k] = into.get(k, 0) + v


def print_turns(rows: dict[str, dict], seconds: float) -> None:
    """Rows: label -> as_deployed's figures (no MAC: the reference; turns: the demo's MAC)."""
    print(f"Table 0b: the demo's mix as the demo runs it, under its manifest's MAC (turns, leader "
          f"surface, 2 packets a turn each side, 4800 bit/s, 300 m; emulator core, lossless), "
          f"beside the same mix without a MAC (the reference above); {seconds:g} s simulated")
    print(f"{'':<26}{'bytes/msg':>10}{'messages':>10}{'packets':>9}{'msgs/pkt':>9}{'bytes/pkt':>10}"
          f"{'air B/s':>9}{'goal':>6}")
    for label in ("unsecured", "secured"):
        for row, r in rows.items():
            n, packets = r[label + " messages"], r[label + " packets"]
            ok = "ok" if r[label] <= GOALS[label] else "MISS"
            air = r[label] * n
            print(f"{label + ', ' + row:<26}{r[label]:>10.1f}{n:>10}{packets:>9}{n / packets:>9.2f}"
                  f"{air / packets:>10.1f}{air / seconds:>9.1f}{GOALS[label]:>6.0f}  {ok}")
    print("what they carry, bytes per delivered message:")
    print(f"{'':<26}" + "".join(f"{k:>9}" for k in PARTS))
    for label in ("unsecured", "secured"):
        for row, r in rows.items():
            print(f"{label + ', ' + row:<26}" + "".join(f"{r[label + ' parts'].get(k, 0):>9.2f}" for k in PARTS))
    print("delivered per topic (both ways), refused stale (reliability / seal), MAC and channel:")
    ids = sorted({i for r in rows.values() for lab in GOALS for i in r[lab + " outcome"]["per_id"]})
    print(f"{'':<26}" + "".join(f"{NAMES.get(i, i):>10}" for i in ids) + f"{'stale':>7}{'seal':>6}  MAC")
    for label in ("unsecured", "secured"):
        for row, r in rows.items():
            o = r[label + " outcome"]
            mac = o.get("mac")
            extra = (f"turns {mac['turns']}, grants {mac['grants_sent']}, ends heard "
                     f"{mac['ends_heard']}, missed {mac['missed']}, from notice {mac['turns_from_notice']} "
                     f"(grant heard after: {mac['recovered']}), lost packets {o['lost']}"
                     if mac else "-")
            print(f"{label + ', ' + row:<26}" + "".join(f"{o['per_id'].get(i, 0):>10}" for i in ids)
                  + f"{o['stale']:>7}{o['seal_stale']:>6}  {extra}")
    print("stale: refused by the receiver's reliability (a command older than its max age, or "
          "any command before the peers' clock offset is measured); seal: refused by the seal")
    print()
