#!/usr/bin/env python3
"""MAC benchmark: the two-way demo (`uwgen demo`: 300 m, 64 B every 0.2 s, 4800 bit/s)
under each way of sharing the channel, each row beside its reference, in one run.

    .venv/bin/python benchmarks/mac_bench.py [--seeds 1] [--per 0,0.2] [--jobs 2]

Per row it prints: packets lost to collisions between the two sides (the emulator's
`lost_collision`, over both nodes) out of packets sent, DESERT's MAC queue high mark and the
packets its full queue dropped (TDMA), commands refused stale at the vehicle, cmd_vel
latency p50 / p95, the demo's exit status, ERROR lines in its logs and the path's largest
deviation from the commanded square (goal: < 0.5 m).

Rows: `none` is the reference (stock CSMA-ALOHA, no turns: what the bridges did before);
`turns` the demo's default; `tdma` DESERT's UW/TDMA as in its samples (frame 1 s, 2 slots,
guard 0.25 s); `tdma 0.35` the guard that leaves a slot less than the period's traffic, with
the bridge pacing to its slot, beside `tdma 0.35 unaware`, its reference: the same DESERT
with bridges that write at their period as if it ran CSMA-ALOHA.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROWS = (
    ("none (reference)", ["--mac", "none"]),
    ("turns", ["--mac", "turns"]),
    ("tdma", ["--mac", "tdma", "--guard", "0.25"]),
    ("tdma 0.35 unaware (reference)", ["--mac", "tdma", "--guard", "0.35", "--bridge-mac", "none"]),
    ("tdma 0.35", ["--mac", "tdma", "--guard", "0.35"]),
)


def run_demo(label: str, extra: list[str], per: float, seed: int, domain: int) -> dict:
    out = Path(tempfile.mkdtemp(prefix="uwgen_macbench_"))
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    cmd = [sys.executable, "-m", "uwgen.cli", "demo", "--quiet", "--per", str(per), "--seed",
           str(seed), "--out", str(out), "--timeout", "400", *extra]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1200)
    text = proc.stdout + proc.stderr
    (out / "demo.txt").write_text(text)
    why = next((ln.split(": ", 1)[-1] for ln in proc.stderr.splitlines() if ln.startswith("uwgen demo:")), "")
    nodes = json.loads((out / "emulator.json").read_text())["nodes"] if (out / "emulator.json").exists() else {}
    vehicle = {}
    if (out / "bridge_vehicle.json").exists():
        vehicle = json.loads((out / "bridge_vehicle.json").read_text())
    reliability = (vehicle.get("link") or {}).get("reliability") or {}
    errors = sum(1 for log in out.glob("*.log") for line in log.read_text(errors="replace").splitlines()
                 if " ERROR " in line or line.startswith("ERROR") or "[ERROR]" in line)
    path = re.search(r"stay within ([\d.]+) m", text)
    cmd_row = re.search(r"/turtle1/cmd_vel .* (\d+) ms +(\d+) ms", text)
    return {
        "label": label, "per": per, "seed": seed, "rc": proc.returncode, "why": why[:80],
        "collisions": sum(n.get("lost_collision", 0) for n in nodes.values()),
        "sent": sum(n.get("packets_sent", 0) for n in nodes.values()),
        "max_mac_queue": max((n.get("max_mac_queue", 0) for n in nodes.values()), default=0),
        "transit": " / ".join(str(max((n.get(f"transit_{q}_ms", 0) for n in nodes.values()), default=0))
                              for q in ("p50", "p95")),
        "queue_drops": sum(n.get("dropped_queue_full", 0) for n in nodes.values()),
        "stale": reliability.get("stale", 0), "errors": errors,
        "path": float(path[1]) if path else float("nan"),
        "cmd": f"{cmd_row[1]} / {cmd_row[2]}" if cmd_row else "-",
        "out": str(out),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", default="0,0.2")
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--jobs", type=int, default=2, help="demos run side by side (own ROS domains)")
    ap.add_argument("--rows", default=",".join(str(i) for i in range(len(ROWS))),
                    help="row indexes to run (default all)")
    args = ap.parse_args()
    base = int(os.environ.get("ROS_DOMAIN_ID", "41"))
    jobs = [(ROWS[int(i)], float(per), int(seed)) for per in args.per.split(",")
            for seed in args.seeds.split(",") for i in args.rows.split(",")]
    print("| row | PER | seed | collisions / packets sent | DESERT MAC queue max | queue-full drops "
          "| stale commands | transit p50 / p95 (ms) | cmd_vel p50 / p95 (ms) | exit | ERROR lines | path max (m) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    with ThreadPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run_demo, label, extra, per, seed, base + 2 * (k % args.jobs))
                   for k, ((label, extra), per, seed) in enumerate(jobs)]
        for f in futures:
            r = f.result()
            print(f"| {r['label']} | {r['per']:g} | {r['seed']} | {r['collisions']} / {r['sent']} | "
                  f"{r['max_mac_queue']} | {r['queue_drops']} | {r['stale']} | {r['transit']} | {r['cmd']} | {r['rc']}{' (' + r['why'] + ')' if r['rc'] else ''} | "
                  f"{r['errors']} | {r['path']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
