"""The long soak: simulated hours of the demo's traffic through the whole link stack.

    /work/main/.venv/bin/python benchmarks/soak.py [--hours 24] [--seed 1]
        [--restart-every 3600] [--per 0.05]

Runs uwgen.emulator.soak.Soak (two Links, the emulator core, a ManualClock; DESERT restarts
at random, on average every --restart-every seconds), traces the heap every simulated hour,
then drains and checks that every counter adds up and nothing was delivered twice. Prints
the figures, the heap per hour and the simulated hours per wall second; exits 1 if a check
fails or the heap grew by more than 64 KiB after the first hour. The test suite runs a
short version (tests/emulator/test_soak.py); UWGEN_SOAK_HOURS=24 runs this one there too.
"""
from __future__ import annotations

import argparse
import sys

from uwgen.emulator.soak import Soak

GROWTH_LIMIT = 64 * 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--restart-every", type=float, default=3600.0, metavar="S")
    parser.add_argument("--per", type=float, default=0.05)
    args = parser.parse_args()

    soak = Soak(seed=args.seed, per=args.per, restart_every=args.restart_every)
    soak.run(args.hours, memory_every=1.0)
    soak.drain()
    rep = soak.report()
    print(f"soak: {rep['simulated_hours']:.2f} simulated h in {rep['wall_seconds']:.0f} s wall "
          f"= {rep['simulated_hours_per_wall_second']:.3f} simulated h per wall second "
          f"(heap traced)")
    print(f"DESERT restarts {rep['restarts']}, reconnects {rep['reconnects']}, per {args.per}")
    print(f"{'flow':28} {'offered':>8} {'delivered':>9} {'repeated':>8} {'corrupt':>7}")
    for name, f in rep["flows"].items():
        offered = "-" if f["offered"] is None else str(f["offered"])
        print(f"{name:28} {offered:>8} {f['delivered']:9d} {f['repeated']:8d} {f['corrupt']:7d}")
    for side, c in rep["emulator"].items():
        lost = {k[5:]: v for k, v in c.items() if k.startswith("lost_") and v}
        print(f"DESERT node {side}: sent {c['packets_sent']} packets, received "
              f"{c['packets_delivered']}, lost on the way to it {lost}, dropped at restarts "
              f"{c['dropped_restart']}")
    print("heap (KiB) per simulated hour: " + " ".join(f"{b / 1024:.1f}" for _, b in rep["memory"]))
    after_warmup = [b for h, b in rep["memory"] if h >= 1.0]
    growth = max(after_warmup) - min(after_warmup) if after_warmup else 0
    ok = True
    try:
        soak.check(drained=True, corrupt_allowed=sys.maxsize)
        print("checks: every counter adds up; nothing delivered twice or out of order")
    except AssertionError as exc:
        print(f"CHECK FAILED: {exc}")
        ok = False
    print(f"heap growth after the first hour: {growth / 1024:.1f} KiB (limit {GROWTH_LIMIT // 1024})")
    if growth > GROWTH_LIMIT:
        ok = False
    print(f"false frames (content wrong, in order): {soak.corrupt()}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
