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

A second table feeds three saturated channels of different sizes and priorities through the
link scheduler: "aligned+fit" (what the Link does) holds the next frame in priority order when it does not
fit (it goes first in the next write, so nothing starves) and fills the room left with the
best frames of other channels that fit; "aligned" stops at the first frame that does not fit.

Under light load (the link not saturated) alignment costs nothing: a write is as small as what
waits. The cost shows only when frames are always waiting and do not divide max_read_length.
"""
from __future__ import annotations

import argparse
import random

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.framing import FrameDecoder, encode_frame
from uwgen.runtime.link.pacing import Outbox, Pacer
from uwgen.runtime.link.scheduler import LinkScheduler

MIXED = {  # channel: (payload bytes, priority, messages per period at most)
    "cmd 22 B prio 10 1/2": (22, 10, 0.5),
    "status 40 B prio 5": (40, 5, None),
    "log 8 B prio 0": (8, 0, None),
}

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


def run_mixed(mrl: int, periods: int, mode: str) -> dict[str, float]:
    """Three saturated channels through the scheduler: payload bytes per period, per channel.
    mode: "cut" (cut-and-fill), "aligned" (stop at the first frame that does not fit),
    "aligned+fit" (fill the rest of the write with the best frames that fit)."""
    clock = ManualClock()
    sched = LinkScheduler(clock)
    for key, (size, prio, rate) in enumerate(MIXED.values()):
        sched.add_channel(key, LinkPolicy(queue="fifo", depth=4, priority=prio, rate=rate))
    box = Outbox(Pacer(mrl, 1.0), aligned=mode != "cut")

    last = [None]

    def pull():
        picked = sched.next_payload(clock.now())
        if picked is None:
            return None
        last[0] = picked[0]
        return encode_frame(picked[1])

    def fit(room):        # as the Link does: never the channel whose frame is held
        picked = sched.next_payload(clock.now(), room - 4, exclude=last[0] if box.pending else None)
        return None if picked is None else encode_frame(picked[1])

    sent = dict.fromkeys(range(len(MIXED)), 0)
    for t in range(periods):
        clock.set(float(t))
        for key, (size, _, _) in enumerate(MIXED.values()):
            while sched.stats()[key]["queued"] < 4:
                sched.offer(key, bytes([0, key]) + bytes(size - 2))
        before = {k: v["sent"] for k, v in sched.stats().items()}
        box.take(float(t), pull, fit if mode == "aligned+fit" else None)
        box.sent(float(t))
        for k, v in sched.stats().items():
            sent[k] += (v["sent"] - before[k]) * list(MIXED.values())[k][0]
    return {name: sent[k] / periods for k, name in enumerate(MIXED)}


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
    print()
    print("three saturated channels through the scheduler (payload B/period per channel, lossless)")
    modes = ("cut", "aligned", "aligned+fit")
    results = {m: run_mixed(a.mrl, a.periods, m) for m in modes}
    head = f"{'channel':<24}" + "".join(f"{m:>14}" for m in modes)
    print(head)
    print("-" * len(head))
    for name in MIXED:
        print(f"{name:<24}" + "".join(f"{results[m][name]:>14.1f}" for m in modes))
    totals = {m: sum(results[m].values()) for m in modes}
    print(f"{'total':<24}" + "".join(f"{totals[m]:>14.1f}" for m in modes)
          + f"   (aligned+fit vs cut {totals['aligned+fit'] / totals['cut'] - 1:+.1%})")


if __name__ == "__main__":
    main()
