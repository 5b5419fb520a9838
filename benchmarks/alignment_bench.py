"""What packet-aligned writes cost in throughput, and what they gain under packet loss.

    .venv/bin/python benchmarks/alignment_bench.py [--mrl 64] [--periods 20000] [--per 0.1]

A saturated Outbox (frames always waiting) writes once per period; each write is one DESERT
packet. Reference: the old cut-and-fill Outbox (`aligned=False`, every write filled to
max_read_length, the last frame cut), measured in the same run on the same frames.

- "payload B/period": payload bytes of the frames completed per write, lossless;
- "cost": how much less aligned writes carry than cut-and-fill (lossless);
- "goodput at PER": payload bytes per period that a receiver decodes when each packet is lost
  with probability PER (same loss pattern for both modes), decoded by uwgen's resyncing decoder
  (an rmw_desert receiver, which cannot resync inside a frame, loses more with cut-and-fill);
- "frames lost/lost pkt": frames the receiver misses per lost packet (cut-and-fill, then aligned).

Under light load (the link not saturated) alignment costs nothing: a write is as small as what
waits. The cost shows only when frames are always waiting and do not divide max_read_length.
"""
from __future__ import annotations

import argparse
import random

from uwgen.runtime.framing import FrameDecoder, encode_frame
from uwgen.runtime.pacing import Outbox, Pacer

WORKLOADS = {
    "6 B (tiny)": lambda r: 6,
    "22 B (Twist)": lambda r: 22,
    "40 B": lambda r: 40,
    "60 B (fills a packet)": lambda r: 60,
    "random 1-60 B": lambda r: r.randint(1, 60),
    "random 1-120 B": lambda r: r.randint(1, 120),
}


def run(mrl: int, periods: int, sizes, aligned: bool, per: float, seed: int) -> tuple[float, float, float]:
    rng = random.Random(seed)
    loss = random.Random(seed + 1)
    box = Outbox(Pacer(mrl, 1.0), aligned=aligned)
    pulled: list[int] = []

    def pull() -> bytes:
        size = sizes(rng)
        pulled.append(size)
        return encode_frame(len(pulled).to_bytes(4, "big")[-min(4, size):] + bytes(max(0, size - 4)))

    stream = bytearray()
    lost = 0
    for t in range(periods):
        batch = box.take(float(t), pull)
        box.sent(float(t))
        if loss.random() >= per:
            stream += batch
        else:
            lost += 1
    sent_payload = sum(pulled[:box.stats.frames_sent])      # payload of the frames completed
    decoded = FrameDecoder().feed(bytes(stream))
    frames_lost = box.stats.frames_sent - len(decoded)
    return sent_payload / periods, sum(len(p) for p in decoded) / periods, frames_lost / max(lost, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mrl", type=int, default=64, help="max_read_length (bytes per packet)")
    ap.add_argument("--periods", type=int, default=20000)
    ap.add_argument("--per", type=float, default=0.1, help="packet error rate for the goodput column")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    print(f"max_read_length {a.mrl} B, {a.periods} saturated periods, goodput at PER {a.per:.0%}")
    head = (f"{'frames':<24}{'cut+fill B/per':>15}{'aligned B/per':>15}{'cost':>8}"
            f"{'cut+fill good':>15}{'aligned good':>14}{'gain':>8}{'frames lost/lost pkt':>22}")
    print(head)
    print("-" * len(head))
    for name, sizes in WORKLOADS.items():
        cut, cut_good, cut_lost = run(a.mrl, a.periods, sizes, False, a.per, a.seed)
        al, al_good, al_lost = run(a.mrl, a.periods, sizes, True, a.per, a.seed)
        print(f"{name:<24}{cut:>15.1f}{al:>15.1f}{(al / cut - 1):>+8.1%}"
              f"{cut_good:>15.1f}{al_good:>14.1f}{(al_good / cut_good - 1):>+8.1%}"
              f"{cut_lost:>12.2f} -> {al_lost:<6.2f}")


if __name__ == "__main__":
    main()
