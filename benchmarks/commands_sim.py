"""The simulated half of benchmarks/commands_bench.py (docs/wire-format.md section 15): the
bench's link and MACs, and, on simulated time (uwgen.emulator.duplex: both sides' real Link
code and the emulator's core), the reliable-topic run and the saturated one-way ledger run.

Reliable topics: the demo's two-way topic mix, 10 minutes per row, and a mission topic of one
20-byte message every 2 s sent `best_effort` and then `reliable`, same seed: delivery ratio,
latency p50/p95, and the air time of acknowledgements (A parts, ack-only packets) and
retransmissions as a share of all bytes the two sides wrote. The measured round trip is the
surface's smoothed round trip (engine.rtt.srtt) when the offered traffic ends: under a MAC it
is the trip of a packet and the report of it with the report's wait for its turn taken off
(turns: from the surface's turn's last packet), so a repair, which waits for the peer's turn
and then this side's, takes about a MAC round (`turn_gap`: the frame, or the round of turns);
p95 is also given against that round.
"""
from __future__ import annotations

import random

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.link.packets import message_measure
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import OVERHEAD, ShortFrameDecoder

# How the two sides share the channel (docs/emulator.md, MACs), at the bench's 1000 m:
# TDMA's guard covers a packet and the range (0.11 + 0.67 s).
MACS = {
    "none": "{mode: none}",
    "tdma": "{mode: tdma, frame: 3.0, guard: 0.8, slots: [surface, vehicle], "
            "max_packet_per_slot: 1000, queue_size: 10, bitrate: 4800, range: 1000}",
    "turns": "{mode: turns, leader: surface, packets: {surface: 4, vehicle: 2}, bitrate: 4800, "
             "range: 1000}",
    # a longer surface turn: its command stream (5/s, priority 10) leaves room for the rest
    "turns8": "{mode: turns, leader: surface, packets: {surface: 8, vehicle: 2}, bitrate: 4800, "
              "range: 1000}",
}
SENDERS = {"surface": 1, "vehicle": 2}


def mac_config(mode: str):
    from uwgen.manifest.mac import mac_from_text
    return mac_from_text(MACS[mode], list(SENDERS))


def scenario(per: float, seed: int, mac: str) -> Scenario:
    """The bench's link (64 B every 0.2 s, 4800 bit/s, 1000 m) under DESERT's MAC for `mac`."""
    from uwgen.emulator.from_manifest import with_mac
    scen = Scenario(nodes=[NodeSpec("surface", position=(0.0, 0.0, 0.0), dest="vehicle", slot=0),
                           NodeSpec("vehicle", position=(1000.0, 0.0, 0.0), dest="surface", slot=1)],
                    period=0.2, max_read_length=64, bitrate=4800.0, per=per, seed=seed)
    return with_mac(scen, mac_config(mac))


# The demo's topic mix (msg_samples/uwgen.yaml) plus the measured mission topic (id 8):
# (side, id, size, every s, policy).
TOPIC_MIX = (
    ("surface", 4, 22, 0.2, LinkPolicy(rate=5, queue="latest", ttl=1.0, priority=10)),
    ("vehicle", 5, 26, 0.5, LinkPolicy(rate=2, queue="latest", ttl=2.0, priority=5)),
    ("vehicle", 6, 30, 5.0, LinkPolicy(rate=0.2, queue="latest", ttl=10.0, priority=1)),
    ("vehicle", 7, 40, 15.0, LinkPolicy(queue="fifo", depth=8, ttl=60.0)),
)
MISSION = 8


class _Wall:
    def __init__(self, clock: ManualClock):
        self.clock = clock

    def now(self) -> float:
        return 1.7e9 + self.clock.now()


def topic_run(per: float, seed: int, reliable: bool, seconds: float = 600.0,
              mac: str = "none", observe=None) -> dict:
    """One simulated run of the topic mix; the mission topic reliable or best effort.
    `observe(sim, macs)`, if given, is called before the run (benchmarks/turns_bench.py)."""
    from uwgen.manifest.model import LinkConfig
    from uwgen.runtime.link.mac import mac_for
    scen = scenario(per, seed, mac)
    config = mac_config(mac)
    macs = {side: mac_for(config, side, SENDERS, LinkConfig(64, 0.2)) for side in SENDERS}
    clock = ManualClock()
    mission = LinkPolicy(queue="fifo", depth=20, ttl=30.0, priority=3, reliable=reliable)
    rel: dict[str, Reliability] = {}
    repair = {"ack": 0, "resent": 0, "mac": 0}

    def hooks_for(side: str):
        r = rel[side] = Reliability(1 if side == "surface" else 2, period=0.2,
                                    reliable={MISSION: 30.0} if reliable else {},
                                    max_ages={i: p.ttl for _, i, _, _, p in TOPIC_MIX} | {MISSION: 30.0},
                                    wall=_Wall(clock), name=side, max_read_length=64,
                                    other_overhead=macs[side].overhead,
                                    turn_gap=macs[side].turn_gap(), settled_by=macs[side].settled_by)
        hooks = r.hooks()

        def counted(source):                # re-sends and copies in spare room: repair bytes
            def count(now, room, *fresh):
                got = source(now, room, *fresh)
                if got is not None:
                    repair["resent"] += message_measure(got[1])
                return got
            return count
        hooks.resend, hooks.copy = counted(hooks.resend), counted(hooks.copy)
        return hooks
    sim = DuplexSim(scen, ("surface", "vehicle"), hooks_for=hooks_for, wire_format=2,
                    clock=clock, step=0.025,
                    link_kw_for=lambda side: {"mac": macs[side], "sender_id": SENDERS[side]})
    for side, link in sim.links.items():
        take = link.connection.outbox.take

        def spy(now, pull, fit=None, take=take):
            batch = take(now, pull, fit)
            for frame in ShortFrameDecoder().feed(batch):
                env = envelope.decode(frame)
                if not env.messages and env.ack is not None:
                    repair["ack"] += len(frame) + OVERHEAD      # the whole ack-only packet
                elif not env.messages:
                    repair["mac"] += len(frame) + OVERHEAD      # a turn's grant or end alone
                elif env.ack is not None:
                    repair["ack"] += 1 + len(env.ack)
            return batch
        link.connection.outbox.take = spy
    for side, ident, _, _, policy in TOPIC_MIX:
        sim.links[side].add_channel(ident, policy)
    sim.links["surface"].add_channel(MISSION, mission)
    rng = random.Random(seed)
    sent_at: dict[int, float] = {}
    for side, ident, size, every, _ in TOPIC_MIX:
        t = rng.uniform(0, every)
        while t < seconds:
            sim.at(t, lambda s=side, i=ident, n=size: sim.links[s].offer(i, bytes((0, i)) + bytes(n - 2)))
            t += every
    for k in range(int(seconds / 2.0)):
        def send(k=k):
            sent_at[k] = clock.now()
            sim.links["surface"].offer(MISSION, bytes((0, MISSION)) + k.to_bytes(2, "big") + bytes(16))
        sim.at(k * 2.0 + 0.3, send)
    # the measured round trip as the traffic ran: the last reports after it stopped (idle
    # repeats, held long) are no round trip of the workload
    srtt: dict[str, float] = {}
    sim.at(seconds, lambda: srtt.setdefault("at_end", rel["surface"].engine.rtt.srtt or float("nan")))
    if observe is not None:
        observe(sim, macs)
    sim.run(seconds + 60.0)
    got: dict[int, float] = {}
    dup = 0
    for t, p in sim.received["vehicle"]:
        if p[1] == MISSION:
            k = int.from_bytes(p[2:4], "big")
            dup += k in got
            got.setdefault(k, t)
    lat = sorted(got[k] - sent_at[k] for k in got)
    written = sum(link.connection.outbox.stats.bytes_sent for link in sim.links.values())
    row = rel["surface"].ledger().get(MISSION, {})
    collisions = sum(sim.core.counters(n)["lost_collision"] for n in SENDERS)
    engine = rel["surface"].engine
    return {"ratio": len(got) / len(sent_at), "p50": _pct(lat, 0.5), "p95": _pct(lat, 0.95),
            "rtt": srtt.get("at_end", float("nan")), "collisions": collisions,
            "round": macs["surface"].turn_gap(), "fast": engine.fast_resends,
            "timer": engine.timer_resends,
            "dup": dup, "ack_share": repair["ack"] / written,
            "resent_share": repair["resent"] / written,
            "lost_on_link": row.get("lost_on_link", 0), "expired": row.get("expired", 0)}


def ledger_run(mac: str, seconds: float = 300.0, per: float = 0.0, seed: int = 5) -> dict:
    """A saturated one-way link (the surface floods a best-effort fifo topic, the vehicle
    sends only its acknowledgements) on simulated time: what the surface's ledger says was
    lost on the link beside what the emulator lost."""
    from uwgen.manifest.model import LinkConfig
    from uwgen.runtime.link.mac import mac_for
    scen = scenario(per, seed, mac)
    config = mac_config(mac)
    macs = {side: mac_for(config, side, SENDERS, LinkConfig(64, 0.2)) for side in SENDERS}
    clock = ManualClock()
    rel: dict[str, Reliability] = {}

    def hooks_for(side: str):
        rel[side] = Reliability(SENDERS[side], period=0.2, reliable={}, max_ages={}, wall=_Wall(clock),
                                name=side, max_read_length=64, other_overhead=macs[side].overhead,
                                turn_gap=macs[side].turn_gap(), settled_by=macs[side].settled_by)
        return rel[side].hooks()
    sim = DuplexSim(scen, ("surface", "vehicle"), hooks_for=hooks_for, wire_format=2, clock=clock,
                    step=0.025, link_kw_for=lambda side: {"mac": macs[side], "sender_id": SENDERS[side]})
    sim.links["surface"].add_channel(MISSION, LinkPolicy(queue="fifo", depth=50, ttl=30.0))
    k = 0
    t = 0.0
    while t < seconds:                                  # 40 B every 0.05 s: 4x what it carries
        sim.at(t, lambda k=k: sim.links["surface"].offer(MISSION, bytes((0, MISSION)) + bytes(38)))
        k += 1
        t += 0.05
    sim.run(seconds + 30.0)
    row = rel["surface"].ledger().get(MISSION, {})
    got = sum(1 for _, p in sim.received["vehicle"] if p[1] == MISSION)
    sent = row.get("sent", 0)
    counters = {n: sim.core.counters(n) for n in SENDERS}
    return {"sent": sent, "delivered": got, "ledger_lost": row.get("lost_on_link", 0),
            "real_lost": sent - got, "ledger_delivered": row.get("delivered", 0),
            "collisions": sum(c["lost_collision"] for c in counters.values()),
            "ack_only_lost": counters["surface"]["lost_collision"] + counters["surface"]["lost_per"]}


def ledger_table(macs: list[str]) -> None:
    print("| mac | messages sent | delivered (vehicle) | really lost | ledger: delivered | "
          "ledger: lost on link | packets lost to collisions |")
    print("|---|---|---|---|---|---|---|")
    for mac in macs:
        r = ledger_run(mac)
        print(f"| {mac} | {r['sent']} | {r['delivered']} | {r['real_lost']} | {r['ledger_delivered']} | "
              f"{r['ledger_lost']} | {r['collisions']} |", flush=True)


def _pct(values: list[float], q: float) -> float:
    return values[min(len(values) - 1, int(q * len(values)))] if values else float("nan")


def topic_table(rates: list[float], seed: int, macs: list[str] = ("none",)) -> None:
    print("| PER | mac | mission topic | delivered | latency p50 / p95 (s) | measured round trip (s) "
          "| p95 / round trip | MAC round (s) | p95 / MAC round | re-sent: report / timer | duplicates "
          "| lost on link (copies) | collisions | acks / bytes written | re-sends / bytes written "
          "| acks + re-sends |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for per in rates:
        for mac in macs:
            for reliable in (False, True):
                r = topic_run(per, seed, reliable, mac=mac)
                print(f"| {per:.0%} | {mac} | {'reliable' if reliable else 'best effort'} | "
                      f"{r['ratio']:.1%} | {r['p50']:.2f} / {r['p95']:.2f} | {r['rtt']:.2f} | "
                      f"{r['p95'] / r['rtt']:.1f} | {r['round']:.2f} | "
                      f"{r['p95'] / r['round'] if r['round'] else float('nan'):.1f} | "
                      f"{r['fast']} / {r['timer']} | "
                      f"{r['dup']} | {r['lost_on_link']} | "
                      f"{r['collisions']} | {r['ack_share']:.1%} | {r['resent_share']:.1%} | "
                      f"{r['ack_share'] + r['resent_share']:.1%} |", flush=True)
