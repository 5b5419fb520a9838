#!/usr/bin/env python3
"""Cut messages against loss: delivered messages and delivered body bytes, with and without
`cut`, at 0 % and 20 % packet error rate (docs/wire-format.md section 14.2).

    .venv/bin/python benchmarks/cut_bench.py [--seconds 300] [--seeds 3]

A cut message needs both of its packets, so on a lossy link cutting trades messages for body
bytes: each cut fills a packet's tail (more bodies per packet), and each lost packet may now
cost one message more (the one cut across it). Two real Links over the emulator's core on
simulated time (uwgen.emulator.linksim), the sender saturated: FIFO Twist-sized messages
(native Twist bodies, 30 or 24 bytes), and three latest topics of the same; per
run the receiver's delivered messages and body bytes per second, and the delivered bodies'
share of the packets the channel carried (max_read_length each; the packets delivered over
1 - PER: at 128 bytes and 4800 bit/s a packet takes longer than the 0.2 s period, so the
sender writes more than the channel carries and a backlog waits in the emulator).
"""
from __future__ import annotations

import argparse
import random
from dataclasses import replace

from uwgen.emulator.linksim import LinkSim
from uwgen.emulator.scenario import NodeSpec, Scenario
from uwgen.manifest.model import LinkPolicy

PERIOD = 0.2
# native Twist bodies as air_bench publishes them: six CBOR floats, two of them float64 (9
# bytes) and four halves (3 bytes), one in seven with a third half (angular.z = 0)
TWIST_BODIES = (30,) * 6 + (24,)
# name: (max_read_length, [(id, queue)])
CASES = {
    "native fifo 64": (64, [(5, "fifo")]),
    "three latest 64": (64, [(11, "latest"), (12, "latest"), (40, "latest")]),
    "native fifo 128": (128, [(5, "fifo")]),
}


def run(case: str, per: float, cut: bool, seconds: float, seed: int) -> dict:
    mrl, topics = CASES[case]
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=PERIOD, max_read_length=mrl, per=per, seed=seed, bitrate=4800.0)
    sim = LinkSim(scen, "a", "b", wire_format=2, sender_id=1, fragment_id=250,
                  rng=random.Random(seed))
    rng = random.Random(seed)
    for ident, queue in topics:
        policy = LinkPolicy(queue=queue, depth=50 if queue == "fifo" else 1)
        sim.sender.add_channel(ident, replace(policy, cut=cut))
        sim.receiver.add_channel(ident, policy)

    def offer(t: float) -> None:
        for ident, _ in topics:
            body = bytes(rng.randrange(256) for _ in range(rng.choice(TWIST_BODIES)))
            sim.sender.offer(ident, bytes((0, ident if ident < 24 else 0x18)) +
                             (bytes((ident,)) if ident >= 24 else b"") + body)
    t = 0.0
    while t < seconds:
        sim.at(t, lambda t=t: offer(t))
        t += PERIOD / 8
    sim.run(seconds)
    got = [p for _, p in sim.received]
    bodies = sum(len(p) - (3 if p[1] == 0x18 else 2) for p in got)
    return {"messages": len(got) / seconds, "bodies": bodies / seconds,
            "share": bodies / max(1, len(sim.packets) / max(1e-9, 1 - per) * mrl),
            "orphans": sim.receiver.stats()["packets"]["cut_orphan"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    print(f"Cut against loss: {args.seconds:.0f} s saturated, {args.seeds} seeds, period {PERIOD} s")
    print(f"{'case':<17}{'PER':>5}  {'cut':<4}{'msgs/s':>8}{'body B/s':>10}{'share':>7}"
          f"{'orphans':>9}{'msgs vs off':>13}{'bodies vs off':>15}")
    for case in CASES:
        for per in (0.0, 0.2):
            rows = {}
            for cut in (False, True):
                rs = [run(case, per, cut, args.seconds, seed) for seed in range(1, args.seeds + 1)]
                rows[cut] = {k: sum(r[k] for r in rs) / len(rs) for k in rs[0]}
            for cut in (False, True):
                r, off = rows[cut], rows[False]
                print(f"{case:<17}{per:>5.0%}  {'on' if cut else 'off':<4}{r['messages']:>8.2f}"
                      f"{r['bodies']:>10.1f}{r['share']:>7.2f}{r['orphans']:>9.0f}"
                      f"{r['messages'] / off['messages']:>13.2f}{r['bodies'] / off['bodies']:>15.2f}")


if __name__ == "__main__":
    main()
