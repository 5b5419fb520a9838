"""Delivery ratio of single-frame and fragmented messages versus packet error rate, before and after.

    .venv/bin/python benchmarks/fec_bench.py [--messages 300] [--plot docs/fec-delivery.png]

Two uwgen Links through the emulator's core (LinkSim: 64-byte packets every 0.2 s, 300 m, a
fixed packet error rate), messages offered back to back on a fifo channel so that a frame is
always waiting (the case where cut-and-fill cuts frames across packets):

- "1-frame": 40-byte payloads (44-byte frames; they fit a packet, so repair does not apply);
- "4-frag": 180-byte payloads: 4 data fragments of at most 51 bytes (48 with repair), or,
  without packet alignment, one 184-byte frame over 3 packets (payloads under 256 bytes not
  fragmented).

Configurations: "before" = cut-and-fill writes, no repair, no fragments under 256 bytes (no
packet alignment, wire-format.md section 11); "aligned" = packet-aligned writes, fragments, no repair; "repair 2" =
aligned + 2 repair fragments per message. Reference columns: (1-p)^4 (four fragments, no repair) and P(>= 4 of 6 arrive).
"""
from __future__ import annotations

import argparse
import logging
import random
from math import comb

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkPolicy

FID = 250
PERS = (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 0.30)
CONFIGS = {"before": (False, 0, True), "aligned": (True, 0, False), "repair 2": (True, 2, False)}
SIZES = {"1-frame": 40, "4-frag": 180}


def delivery(size: int, aligned: bool, repair: int, whole: bool, per: float, messages: int,
             seed: int) -> float:
    scenario = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                               NodeSpec("b", position=(300, 0, 0), dest="a")],
                        period=0.2, max_read_length=64, per=per, seed=seed, bitrate=4800.0)
    sim = LinkSim(scenario, "a", "b", aligned=aligned, fragment_id=FID, rng=random.Random(seed),
                  fragment_timeout=30.0)
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=messages, repair=repair), whole=whole)
    for i in range(messages):
        sim.at(0.0, lambda i=i: sim.sender.offer(7, b"\x00\x07" + i.to_bytes(4, "big") + bytes(size - 6)))
    packets = messages * (-(-(size + 4) // 64) + 1 + repair) + 10      # room for every fragment
    sim.run(packets * 0.2 * 1.1 + 40)
    got = {p for _, p in sim.received if len(p) == size}
    return len(got) / messages


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--plot", default=None, help="write a PNG of the curves here (matplotlib)")
    a = ap.parse_args()
    logging.disable(logging.WARNING)          # the receiver logs every lost transfer
    results: dict[tuple[str, str], list[float]] = {}
    for kind, size in SIZES.items():
        for name, (aligned, repair, whole) in CONFIGS.items():
            results[kind, name] = [delivery(size, aligned, repair, whole, p, a.messages, a.seed + i)
                                   for i, p in enumerate(PERS)]
    print(f"delivery ratio vs packet error rate, {a.messages} messages per point, "
          "64 B packets every 0.2 s, through the emulator core")
    head = f"{'PER':>5}" + "".join(f"{k + ' ' + n:>18}" for k in SIZES for n in CONFIGS) + f"{'(1-p)^4':>10}{'P(>=4 of 6)':>13}"
    print(head)
    print("-" * len(head))
    for i, p in enumerate(PERS):
        row = "".join(f"{results[k, n][i]:>18.3f}" for k in SIZES for n in CONFIGS)
        binom = sum(comb(6, j) * (1 - p) ** j * p ** (6 - j) for j in range(4, 7))
        print(f"{p:>5.0%}{row}{(1 - p) ** 4:>10.3f}{binom:>13.3f}")
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 4.2))
        x = [100 * p for p in PERS]
        styles = {"before": ":", "aligned": "--", "repair 2": "-"}
        colors = {"1-frame": "tab:blue", "4-frag": "tab:red"}
        for (kind, name), ys in results.items():
            ax.plot(x, ys, styles[name], color=colors[kind], marker="o", ms=3,
                    label=f"{SIZES[kind]} B {kind}: {name}")
        ax.plot(x, [(1 - p) ** 4 for p in PERS], color="grey", lw=0.8, label="(1-p)^4 reference")
        ax.set_xlabel("packet error rate (%)")
        ax.set_ylabel("messages delivered")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
        ax.set_title("Delivery vs packet loss: cut-and-fill, aligned, aligned + 2 repair fragments", fontsize=9)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
        print(f"plot: {a.plot}")


if __name__ == "__main__":
    main()
