#!/usr/bin/env python3
"""Secure link benchmark: bytes per frame and encode+decode time with security off, sign and
encrypt, for the benchmark messages, against `off` measured in the same run.

    .venv/bin/python benchmarks/security_bench.py [--quick]

A round trip is: generated codec encode, LinkGuard.protect (sign/encrypt), frame, then
LinkGuard.unprotect and codec decode into rclpy instances, between two guards of one
network (sender and receiver state files in a temporary folder, so the fsync'd
reservations, one per 256 frames sent and one per 16 accepted, are in the time; `us no
disk` is the same with blocks so large that nothing is written: the cost of the crypto). Bytes
are those of the usual frame; one frame in 32 (and the first 3 after a start, and one after 30 s
without any) carries a sync word, 4 bytes more, which the `avg B` column spreads over all
frames of a sender that sends at least one frame a second.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from codec_bench import per_call_us, samples  # noqa: E402  (the codec benchmark's messages and timer)

from uwgen.codegen import generate  # noqa: E402
from uwgen.runtime.framing import OVERHEAD as FRAME_OVERHEAD  # noqa: E402
from uwgen.security import wire  # noqa: E402
from uwgen.security.guard import SYNC_EVERY, GuardConfig, LinkGuard  # noqa: E402
from uwgen.security.state import RECV_BLOCK, SEND_BLOCK  # noqa: E402

MESSAGES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/Pose", "sensor_msgs/msg/NavSatFix",
            "sensor_msgs/msg/Imu", "sensor_msgs/msg/BatteryState", "std_msgs/msg/String")
MODES = ("off", "sign", "encrypt")


def guards(folder: Path, mode: str, disk: bool = True) -> tuple[LinkGuard, LinkGuard]:
    """A sender and a receiver; without `disk` their blocks are so large they never write."""
    key = bytes(range(32))
    modes = {4: mode}
    kw = {} if disk else {"send_block": 10**12, "recv_block": 10**12}
    tag = f"{mode}{'' if disk else '.nodisk'}"
    tx = LinkGuard.for_key(key, GuardConfig("bench", 1, {2: "rx"}, modes), folder / f"{tag}.tx", **kw)
    rx = LinkGuard.for_key(key, GuardConfig("bench", 2, {1: "tx"}, modes), folder / f"{tag}.rx", **kw)
    return tx, rx


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations")
    args = parser.parse_args()
    number = 500 if args.quick else 5000

    msgs = samples()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        pkg = generate(folder / "gen", "uwgen_secbench", names=list(MESSAGES))
        pairs = {m: guards(folder, m) for m in MODES if m != "off"}
        bare = {m: guards(folder, m, disk=False) for m in MODES if m != "off"}
        print(f"{'message':<14}{'mode':<9}{'frame B':>8}{'avg B':>8}{'+B':>5}{'us':>9}{'x off':>7}"
              f"{'us no disk':>12}{'x off':>7}")
        for name in MESSAGES:
            codec, msg = pkg.codec(name), msgs[name]
            base_len = base_us = None
            for mode in MODES:
                if mode == "off":
                    def trip(codec=codec, msg=msg):
                        codec.decode(codec.encode(msg, [0, 4]), (0, 4))
                    size = len(codec.encode(msg, [0, 4])) + FRAME_OVERHEAD
                    us = us_bare = per_call_us(trip, number)
                    base_len, base_us = size, us
                else:
                    def make(tx, rx, codec=codec, msg=msg):
                        def trip():
                            out = rx.unprotect(tx.protect(4, codec.encode(msg, [0, 4])))
                            codec.decode(out, (0, 4))
                        return trip
                    tx, rx = pairs[mode]
                    plain = codec.encode(msg, [0, 4])
                    protected = tx.protect(4, plain)
                    assert rx.unprotect(protected) == plain
                    size = len(plain) + wire.OVERHEAD + FRAME_OVERHEAD
                    us = per_call_us(make(tx, rx), number)
                    us_bare = per_call_us(make(*bare[mode]), number)
                avg = size + (wire.SYNC_BYTES / SYNC_EVERY if mode != "off" else 0)
                print(f"{name.split('/')[-1]:<14}{mode:<9}{size:>8}{avg:>8.1f}{size - base_len:>5}"
                      f"{us:>9.1f}{us / base_us:>7.2f}{us_bare:>12.1f}{us_bare / base_us:>7.2f}")
        for tx, rx in (*pairs.values(), *bare.values()):
            st = rx.stats()
            assert st["dropped"] == 0 and st["verified"] > 0, st
        tx, _ = pairs["sign"]
        write_us = per_call_us(lambda: tx.store.save(tx.state), 20)
        per_frame = write_us * (1 / SEND_BLOCK + 1 / RECV_BLOCK)
        print(f"one fsync'd state-file write: {write_us:.0f} us; one per {SEND_BLOCK} frames sent and "
              f"one per {RECV_BLOCK} accepted: {per_frame:.1f} us per frame (the gap between the "
              "two time columns; it follows the disk)")
        print(f"overhead goal: <= 10 B per frame; measured {wire.OVERHEAD} B "
              f"({wire.SYNC_OVERHEAD} B on sync frames, 1 in {SYNC_EVERY})")


if __name__ == "__main__":
    main()
