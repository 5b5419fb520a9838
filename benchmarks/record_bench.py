#!/usr/bin/env python3
"""Recording benchmark: what a bridge's recorder (uwgen.bridge.recorder) costs per record,
next to serializing the same message with rclpy (the least a ROS recorder does), same run.

    .venv/bin/python benchmarks/record_bench.py [--seconds 50]

Plays `--seconds` of the demo link's worst load on a bridge at 1 000 Twist/s: the 50
messages a second its latest-only poll takes, 5 packets written and 5 read, a status
snapshot every 2 s and one chunk ended a second, for each chunk compression. Prints the CPU
(this process, writer thread included) per simulated second, per record, the file size, and
rclpy's serialize_message per message measured alongside.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from geometry_msgs.msg import Twist
from rclpy.serialization import serialize_message

from uwgen.bridge.recorder import BridgeRecorder, RecordOptions

MESSAGES, PACKETS = 50, 10        # a second of the bridge at 1 000 msg/s (polled), 5 tx + 5 rx


def run(root: Path, compression: str, seconds: int) -> tuple[float, int]:
    path = root / f"{compression}.mcap"
    rec = BridgeRecorder(RecordOptions(path), network="bench", side="surface",
                         link_config=SimpleNamespace(max_read_length=64, period=0.2),
                         topics={"/cmd_vel": "out"}, compression=compression,
                         tick=3600, flush_every=3600)       # the bench ends chunks itself
    rec.topic("/cmd_vel", Twist)
    status = {"topics": {"/cmd_vel": {"taken": 0, "link": {"queued": 1, "sent": 0}}}, "link": {}}
    msg, packet = Twist(), os.urandom(60)
    start = time.process_time()
    for second in range(seconds):
        for k in range(MESSAGES):
            msg.linear.x = (second * MESSAGES + k) * 1e-3
            rec.message("/cmd_vel", msg, b"%d" % k, published=time.time())
        for k in range(PACKETS):
            rec.packet(0.0, "tx" if k % 2 else "rx", packet, "sent" if k % 2 else "delivered 1")
        if second % 2 == 0:
            rec.status(status, final=True)
        rec.out.sync()
    rec.close()
    return time.process_time() - start, path.stat().st_size


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=int, default=50)
    args = parser.parse_args()
    msg = Twist()
    n = 20000
    t0 = time.process_time()
    for k in range(n):
        msg.linear.x = k * 1e-3
        serialize_message(msg)
    serialize_us = (time.process_time() - t0) / n * 1e6
    records = args.seconds * (MESSAGES + PACKETS) + args.seconds // 2
    print(f"{'compression':<12}{'ms CPU per s':>13}{'us per record':>14}{'KiB per min':>12}{'x serialize':>12}")
    with tempfile.TemporaryDirectory() as tmp:
        for compression in ("zstd", "lz4", "none"):
            cpu, size = run(Path(tmp), compression, args.seconds)
            per_record = cpu / records * 1e6
            print(f"{compression:<12}{cpu / args.seconds * 1e3:>13.2f}{per_record:>14.1f}"
                  f"{size / 1024 / args.seconds * 60:>12.0f}{per_record / serialize_us:>12.1f}")
    print(f"reference: rclpy serialize_message of a Twist, {serialize_us:.1f} us (same run); a "
          f"second is {MESSAGES} messages taken, {PACKETS} packets, a status every 2 s, one chunk")
    return 0


if __name__ == "__main__":
    sys.exit(main())
