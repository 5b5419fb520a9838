#!/usr/bin/env python3
"""Turns benchmark (docs/wire-format.md section 16, uwgen.runtime.link.turn_mac.TurnMac): what a
lost packet costs a round of turns, on simulated time.

    .venv/bin/python benchmarks/turns_bench.py [--per 0.2] [--seeds 3,5,7] [--before main]

The workload is commands_bench's reliable-topic run under `turns` (the demo's two-way topic
mix and a reliable mission topic; 64 B every 0.2 s, 4800 bit/s, 1000 m; the turns granted
in its 10 minutes of traffic, per seed). Every packet the emulator's core carries is traced (who wrote it and when, its C
items, when it reached the other side or why it was lost), and each turn the leader granted
is put in one class by what the channel did to it:

- `ended`: the follower's end reached the leader before the leader wrote again;
- `grant lost`: the follower wrote nothing in that turn (grant lost, and its notice with it
  or there was none);
- `answers lost`: the follower answered and none of its packets reached the leader;
- `end lost`: the leader heard some of the answer, not its end;
- `late`: the end reached the leader after the leader had written again.

Per class: turns, and the mean time the leader kept the channel idle past what it could
know, `idle`: from the arrival (or loss) of the follower's last packet of the turn to the
leader's next write (`grant lost`: from the grant's write, the whole wait). Beside it: the
turns missed while traffic was offered (beside the leader's `missed` counter: the whole
run, its idle minute after the traffic included), the idle time after losses per round
(what lost packets cost a round on average), the mean round (grant to grant), the follower's start after
hearing its grant (mean / max), the sides' collisions, and the reliable topic's p95 over
its measured round trip. `--before REF` runs the same measurement on the uwgen of git
revision REF (exported to a temporary directory) first: the reference, same run.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SECONDS = 600.0         # of offered traffic (commands_sim.topic_run's default)
CLASSES = ("ended", "grant lost", "answers lost", "end lost", "late")


class Trace:
    """Every packet's fate at its destination, from the emulator core of a DuplexSim."""

    def __init__(self):
        self.packets: list[dict] = []

    def attach(self, sim, macs) -> None:
        from uwgen.runtime.link.mac import decode_items
        from uwgen.runtime.wire import envelope
        from uwgen.runtime.wire.framing import ShortFrameDecoder
        core = sim.core
        rx_end = core._rx_end

        def traced(arr, t):
            pkt, receiver = arr.packet, arr.receiver
            before = core.counters(receiver)["packets_delivered"] if pkt.dest == receiver else None
            rx_end(arr, t)
            if before is None:
                return
            items = []
            for frame in ShortFrameDecoder().feed(pkt.data):
                items += decode_items(envelope.decode(frame).control or b"")
            self.packets.append({
                "source": pkt.source, "written": pkt.queued_at, "sent": pkt.sent_at, "end": arr.end,
                "ok": core.counters(receiver)["packets_delivered"] > before,
                "grant": next((i.count for i in items if i.code == 2), None),
                "ended": any(i.code == 3 for i in items)})
        core._rx_end = traced


def analyse(packets: list[dict], until: float, leader: str = "surface") -> dict:
    """The turns granted before `until` (the end of the offered traffic: after it the
    leader's turns are a lone grant), classed (module doc)."""
    ours = sorted((p for p in packets if p["source"] == leader), key=lambda p: p["written"])
    theirs = sorted((p for p in packets if p["source"] != leader), key=lambda p: p["written"])
    grants = [p for p in ours if p["grant"] and p["written"] < until]
    idle = {c: [] for c in CLASSES}
    starts, rounds = [], []
    for k, g in enumerate(grants[:-1]):
        nxt = grants[k + 1]["written"]
        rounds.append(nxt - g["written"])
        back = next((p["written"] for p in ours if p["written"] > g["written"]), nxt)
        answer = [p for p in theirs if g["written"] < p["written"] <= nxt]
        heard = [p for p in answer if p["ok"]]
        end = next((p for p in heard if p["ended"]), None)
        if answer and g["ok"]:
            starts.append(answer[0]["written"] - g["end"])
        if end is not None:
            cls = "ended" if end["end"] <= back else "late"
        elif not answer:
            cls = "grant lost"
        elif not heard:
            cls = "answers lost"
        else:
            cls = "end lost"
        last = max((p["end"] for p in answer if p["written"] < back), default=g["written"])
        idle[cls].append(back - last)
    lost = [x for c, v in idle.items() if c != "ended" for x in v]
    return {"turns": {c: len(v) for c, v in idle.items()}, "missed_traffic": len(lost),
            "loss_idle": sum(lost) / max(1, sum(len(v) for v in idle.values())),
            "idle": {c: statistics.fmean(v) if v else float("nan") for c, v in idle.items()},
            "round": statistics.fmean(rounds), "start_mean": statistics.fmean(starts),
            "start_max": max(starts)}


def measure(per: float, seed: int) -> dict:
    sys.path.insert(0, str(HERE))
    import commands_sim as cb
    trace = Trace()
    seen = {}

    def observe(sim, macs):
        trace.attach(sim, macs)
        seen["macs"] = macs
    r = cb.topic_run(per, seed, True, seconds=SECONDS, mac="turns", observe=observe)
    out = analyse(trace.packets, SECONDS)
    lead = seen["macs"]["surface"].stats()
    out.update(missed=lead["missed"], grants=lead["grants_sent"], collisions=r["collisions"],
               p95=r["p95"], rtt=r["rtt"], p95_rtt=r["p95"] / r["rtt"])
    return out


FLEET_MAC = "{mode: turns, leader: surface, bitrate: 4800, range: 1000}"


def fleet_measure(vehicles: int, per: float, seed: int, seconds: float = 300.0) -> dict:
    """One leader and `vehicles` followers on a 500 m circle around it (the manifest's range:
    the farthest two apart), each side's Link under its TurnMac over the emulator's core,
    best-effort traffic (the surface's orders to all every 0.5 s, each vehicle's telemetry
    every second); the first vehicle restarts (a new Link, nothing kept) a third of the way
    in. Collisions between the sides, the leader's missed turns, each vehicle's ended
    turns after its restart."""
    import math

    from uwgen.emulator import BROADCAST, NodeSpec, Scenario
    from uwgen.emulator.duplex import DuplexSim
    from uwgen.emulator.from_manifest import with_mac
    from uwgen.manifest.mac import mac_from_text
    from uwgen.manifest.model import LinkConfig, LinkPolicy
    from uwgen.runtime.link.mac import mac_for
    names = ["surface"] + [f"auv{i + 1}" for i in range(vehicles)]
    senders = {n: i + 1 for i, n in enumerate(names)}
    config = mac_from_text(FLEET_MAC, names)
    nodes = [NodeSpec("surface", position=(0.0, 0.0, 0.0), dest=BROADCAST)]
    for i, n in enumerate(names[1:]):
        a = 2 * math.pi * i / vehicles
        nodes.append(NodeSpec(n, position=(500 * math.cos(a), 500 * math.sin(a), 0.0), dest="surface"))
    scen = with_mac(Scenario(nodes=nodes, period=0.2, max_read_length=64, per=per, seed=seed), config)
    macs = {}

    def link_kw(side):
        macs[side] = mac_for(config, side, senders, LinkConfig(64, 0.2))
        return {"mac": macs[side], "sender_id": senders[side]}
    sim = DuplexSim(scen, tuple(names), wire_format=2, step=0.025, link_kw_for=link_kw)
    policy = LinkPolicy(queue="latest", ttl=5.0, rate=5)

    def channels(side):
        sim.links[side].add_channel(senders[side], policy)
    for n in names:
        channels(n)
    restarted = {}

    def restart():
        sim.restart(names[1])
        channels(names[1])
        restarted["at"] = sim.clock.now()
        restarted["mac"] = macs[names[1]]
    sim.at(seconds / 3, restart)
    for n in names:
        every = 0.5 if n == "surface" else 1.0
        t = random.Random(f"{seed}{n}").uniform(0, every)
        while t < seconds:
            sim.at(t, lambda n=n: sim.links[n].offer(senders[n], bytes((0, senders[n])) + bytes(18)))
            t += every
    sim.run(seconds)
    lead = macs["surface"].stats()
    return {"collisions": sum(sim.core.counters(n)["lost_collision"] for n in names),
            "grants": lead["grants_sent"], "ends": lead["ends_heard"], "missed": lead["missed"],
            "restarted_turns": restarted["mac"].stats()["turns"],
            "received": {n: len(sim.received[n]) for n in names}}


def export(rev: str) -> str:
    """uwgen as at git revision `rev`, in a temporary directory."""
    root = HERE.parent
    out = tempfile.mkdtemp(prefix="uwgen_turns_ref_")
    archive = subprocess.run(["git", "-C", str(root), "archive", rev, "uwgen"], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", out], input=archive, check=True)
    return out


def rows(per: float, seeds: list[int], code: str | None, fleet: int = 0) -> list[dict]:
    if code is None:
        return [fleet_measure(fleet, per, s) if fleet else measure(per, s) for s in seeds]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([code, str(HERE)])}
    got = subprocess.run([sys.executable, __file__, "--json", "--per", str(per), "--fleet", str(fleet),
                          "--seeds", ",".join(map(str, seeds))], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(got.splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", type=float, default=0.2)
    ap.add_argument("--seeds", default="3,5,7")
    ap.add_argument("--before", metavar="REV", help="also measure uwgen at this git revision")
    ap.add_argument("--fleet", type=int, default=0, metavar="N",
                    help="instead: one leader and N followers (fleet_measure), 5 minutes a seed")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    if args.json:
        print(json.dumps(rows(args.per, seeds, None, args.fleet)))
        return 0
    runs = []
    if args.before:
        runs.append((f"before ({args.before})", rows(args.per, seeds, export(args.before), args.fleet)))
    runs.append(("this build", rows(args.per, seeds, None, args.fleet)))
    if args.fleet:
        print(f"PER {args.per:.0%}, turns, 1 leader + {args.fleet} followers, seeds {args.seeds}")
        print("| code | seed | grants | ends heard | missed | collisions | restarted follower's "
              "turns | packets received per side |")
        print("|---|---|---|---|---|---|---|---|")
        for name, results in runs:
            for seed, r in zip(seeds, results):
                print(f"| {name} | {seed} | {r['grants']} | {r['ends']} | {r['missed']} | "
                      f"{r['collisions']} | {r['restarted_turns']} | "
                      f"{' '.join(str(v) for v in r['received'].values())} |")
        return 0
    print(f"PER {args.per:.0%}, turns, seeds {args.seeds}")
    print("| code | seed | turns | " + " | ".join(f"{c} (idle s)" for c in CLASSES)
          + " | missed (traffic / whole run) | idle after losses per round (s) | round (s) "
          "| follower start mean / max (s) | collisions | p95 / rtt |")
    print("|---|---|---|" + "---|" * len(CLASSES) + "---|---|---|---|---|---|")
    for name, results in runs:
        for seed, r in zip(seeds, results):
            n = sum(r["turns"].values())
            cells = " | ".join(f"{r['turns'][c]} ({r['idle'][c]:.2f})" for c in CLASSES)
            print(f"| {name} | {seed} | {n} | {cells} | {r['missed_traffic']} / {r['missed']} | "
                  f"{r['loss_idle']:.2f} | {r['round']:.2f} | "
                  f"{r['start_mean']:.2f} / {r['start_max']:.2f} | {r['collisions']} | "
                  f"{r['p95_rtt']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
