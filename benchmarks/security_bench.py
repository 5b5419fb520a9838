#!/usr/bin/env python3
"""Secure link benchmark: bytes per frame and encode+decode time with security off, sign and
encrypt, for the benchmark messages, against `off` measured in the same run, and against the
design of issue 9 that this one replaced (same run, same disk).

    .venv/bin/python benchmarks/security_bench.py [--quick]

A round trip is: generated codec encode, LinkGuard.protect (sign/encrypt), frame, then
LinkGuard.unprotect and codec decode into rclpy instances, between two guards of one network.
The guards keep nothing on disk (a fresh epoch per start), so `us` is all crypto and codec.

`before` is issue 9's design: the same AES-CCM per frame, plus a state file written (temporary
file, fsync, rename, fsync of the folder) once per 256 frames sent and once per 16 accepted;
that write is timed here with the same write path, and its share per frame added. Bytes: issue
9's sync word was 4 bytes on 1 frame in 32, this one is 13 bytes (number bits, epoch, time) on 1
frame in 64 (and the first 3 of each epoch, and one after 30 s without any); `avg B` spreads
the sync words over all frames of a sender that sends at least one frame every 30 s.
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
from uwgen.security.files import write_private  # noqa: E402
from uwgen.security.guard import SYNC_EVERY, GuardConfig, LinkGuard  # noqa: E402

BEFORE_SYNC_BYTES, BEFORE_SYNC_EVERY = 4, 32     # issue 9's sync word
BEFORE_SEND_BLOCK, BEFORE_RECV_BLOCK = 256, 16   # its state-file writes: per frames sent, accepted

MESSAGES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/Pose", "sensor_msgs/msg/NavSatFix",
            "sensor_msgs/msg/Imu", "sensor_msgs/msg/BatteryState", "std_msgs/msg/String")
MODES = ("off", "sign", "encrypt")


def guards(mode: str) -> tuple[LinkGuard, LinkGuard]:
    """A sender and a receiver of one network (nothing on disk)."""
    key = bytes(range(32))
    modes = {4: mode}
    return (LinkGuard(key, GuardConfig("bench", 1, {2: "rx"}, modes)),
            LinkGuard(key, GuardConfig("bench", 2, {1: "tx"}, modes)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations")
    args = parser.parse_args()
    number = 500 if args.quick else 5000

    msgs = samples()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        state = folder / "before.state"
        record = b'{"floors": {"2": 1234567}, "key_id": "0123456789abcdef", "reserved": 123456, "version": 1}\n'
        write_us = per_call_us(lambda: write_private(state, record), 20)
        before_disk = write_us * (1 / BEFORE_SEND_BLOCK + 1 / BEFORE_RECV_BLOCK)
        pkg = generate(folder / "gen", "uwgen_secbench", names=list(MESSAGES))
        pairs = {m: guards(m) for m in MODES if m != "off"}
        print(f"{'message':<14}{'mode':<9}{'frame B':>8}{'+B':>4}{'avg B before':>13}{'avg B now':>10}"
              f"{'us before':>10}{'x off':>7}{'us now':>8}{'x off':>7}")
        for name in MESSAGES:
            codec, msg = pkg.codec(name), msgs[name]
            base_len = base_us = None
            for mode in MODES:
                if mode == "off":
                    def trip(codec=codec, msg=msg):
                        codec.decode(codec.encode(msg, [0, 4]), (0, 4))
                    size = len(codec.encode(msg, [0, 4])) + FRAME_OVERHEAD
                    us = before = per_call_us(trip, number)
                    base_len, base_us = size, us
                    avg_before = avg_now = size
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
                    before = us + before_disk
                    avg_before = size + BEFORE_SYNC_BYTES / BEFORE_SYNC_EVERY
                    avg_now = size + wire.SYNC_BYTES / SYNC_EVERY
                print(f"{name.split('/')[-1]:<14}{mode:<9}{size:>8}{size - base_len:>4}{avg_before:>13.2f}"
                      f"{avg_now:>10.2f}{before:>10.1f}{before / base_us:>7.2f}{us:>8.1f}{us / base_us:>7.2f}")
        for tx, rx in pairs.values():
            st = rx.stats()
            assert st["dropped"] == 0 and st["verified"] > 0, st
        print(f"before: one fsync'd state-file write took {write_us:.0f} us here; one per "
              f"{BEFORE_SEND_BLOCK} frames sent and one per {BEFORE_RECV_BLOCK} accepted: "
              f"{before_disk:.1f} us per frame (it follows the disk). Now: no state write at all.")
        print(f"overhead goal: <= 10 B per frame; measured {wire.OVERHEAD} B, {wire.SYNC_OVERHEAD} B on "
              f"sync frames (1 in {SYNC_EVERY}): {wire.OVERHEAD + wire.SYNC_BYTES / SYNC_EVERY:.2f} B on "
              f"average (before: {wire.OVERHEAD + BEFORE_SYNC_BYTES / BEFORE_SYNC_EVERY:.2f} B); at "
              f"200 bit/s {8 * (wire.OVERHEAD + wire.SYNC_BYTES / SYNC_EVERY) / 200:.3f} s of air time "
              f"per frame (before {8 * (wire.OVERHEAD + BEFORE_SYNC_BYTES / BEFORE_SYNC_EVERY) / 200:.3f} s)")


if __name__ == "__main__":
    main()
