"""The long soak: simulated hours of the demo's traffic through the whole link stack.

    /work/main/.venv/bin/python benchmarks/soak.py [--hours 24] [--seed 1]
        [--restart-every 3600] [--per 0.05]

Runs uwgen.emulator.soak.Soak (two Links, the emulator core, a ManualClock; DESERT restarts
at random, on average every --restart-every seconds) with binary payloads full of the
framing's 0x99 / 0x55 bytes, records the process's resident set (RSS) from the start and
through the whole run, then drains and checks: every counter adds up, nothing delivered
twice, out of order or with wrong content (no false frame allowed), and per flow the ledger
closes (sent = delivered + lost; the receiver never counts more lost than did not arrive;
the sending link's own ledger, once it reports one, says exactly that: wire-format.md section 15.7). Prints the
figures, the ledger, the RSS samples and the simulated hours per wall second; exits 1 if a
check fails or RSS grew by more than GROWTH_LIMIT over the run (warm-up included). The test
suite runs a short version (tests/emulator/test_soak.py); UWGEN_SOAK_HOURS=24 runs the long
one there too.
"""
from __future__ import annotations

import argparse

from uwgen.emulator.soak import Soak

# RSS growth allowed over the whole run, from the first sample (before any traffic): the
# warm-up of queues and counters is about 0.1 MiB; a leak of 8 bytes a message is ~8 MiB a day.
GROWTH_LIMIT = 4 * 1024 * 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hours", type=float, default=24.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--restart-every", type=float, default=3600.0, metavar="S")
    parser.add_argument("--per", type=float, default=0.05)
    parser.add_argument("--samples", type=int, default=48,
                        help="RSS samples over the run (the first before any traffic)")
    args = parser.parse_args()

    soak = Soak(seed=args.seed, per=args.per, restart_every=args.restart_every)
    soak.run(args.hours, memory_every=args.hours / args.samples)
    soak.drain()
    rep = soak.report()
    print(f"soak: {rep['simulated_hours']:.2f} simulated h in {rep['wall_seconds']:.0f} s wall "
          f"= {rep['simulated_hours_per_wall_second']:.3f} simulated h per wall second")
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
    print(f"{'ledger per flow':28} {'sent':>8} {'delivered':>9} {'lost':>6} {'seen lost':>9} {'link ledger':>11}")
    for name, row in soak.ledger().items():
        link = "not yet" if row["link"] is None else f"{row['link']['lost_on_link']} lost"
        print(f"{name:28} {row['sent']:8d} {row['delivered']:9d} {row['lost']:6d} {row['lost_seen']:9d} {link:>11}")
    samples = rep["memory"]
    print(f"RSS (MiB) at {len(samples)} points from {samples[0][0]:.2f} h to {samples[-1][0]:.2f} h: "
          + " ".join(f"{b / 1048576:.2f}" for _, b in samples))
    growth = max(b for _, b in samples) - samples[0][1]
    ok = True
    try:
        soak.check(drained=True, corrupt_allowed=0)
        print("checks: every counter adds up; nothing delivered twice, out of order or with wrong "
              "content; every flow's ledger closes")
    except AssertionError as exc:
        print(f"CHECK FAILED: {exc}")
        ok = False
    print(f"RSS growth over the whole run: {growth / 1048576:.2f} MiB (limit {GROWTH_LIMIT / 1048576:.0f})")
    if growth > GROWTH_LIMIT:
        print("CHECK FAILED: memory grew")
        ok = False
    print(f"false frames (content wrong, in order): {soak.corrupt()}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
