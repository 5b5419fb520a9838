#!/usr/bin/env python3
"""Reads a commands_bench --trace file and prints, for each failed call or goal, what
happened to its messages between its round's start and the next round: every offer (first
or copy), every packet carrying one, every arrival and every refusal at the receiving judge,
in seconds from the round's start. With --all it prints every round.

    python benchmarks/trace_commands.py TRACE.jsonl [--all]
"""
from __future__ import annotations

import argparse
import json
import sys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trace")
    ap.add_argument("--all", action="store_true")
    args = ap.parse_args()
    rows = [json.loads(line) for line in open(args.trace) if line.strip().startswith("{")]
    rounds = [r for r in rows if r.get("ev") == "round"]
    failed = {}
    for r in rows:
        if r.get("ev") == "failed":
            failed.setdefault(r["i"], []).append(r["what"])
    for k, start in enumerate(rounds):
        i = start["i"]
        if not args.all and i not in failed:
            continue
        end = rounds[k + 1]["t"] if k + 1 < len(rounds) else float("inf")
        print(f"== round {i}: failed {failed.get(i, [])}")
        for r in rows:
            if "t" not in r or not start["t"] <= r["t"] < end or r.get("ev") in ("round",):
                continue
            ev = r.get("ev")
            t = r["t"] - start["t"]
            if ev == "packet":
                cmds = [m for m in r["m"] if m[2:4] in ("14", "09")]
                if cmds:
                    print(f"  {t:6.2f} {r['side'][:3]} packet #{r['no']} {' '.join(cmds)}")
            elif ev in ("offer", "in"):
                print(f"  {t:6.2f} {r['side'][:3]} {ev:5s} {r['p']}")
            elif ev == "refused" and r["key"] in (9, 20):
                print(f"  {t:6.2f} {r['side'][:3]} REFUSED key {r['key']} age {r['age']}")
            elif ev == "failed":
                print(f"  {t:6.2f} FAILED {r['what']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
