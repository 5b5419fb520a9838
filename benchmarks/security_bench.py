#!/usr/bin/env python3
"""Secure link benchmark: bytes per frame and encode+decode time with security off, sign and
encrypt, for the benchmark messages, against `off` measured in the same run, and against a
seal that keeps its counters in a state file (same run, same disk).

    .venv/bin/python benchmarks/security_bench.py [--quick]

A round trip is: generated codec encode, LinkGuard.protect (sign/encrypt), frame, then
LinkGuard.unprotect and codec decode into rclpy instances, between two guards of one network.
The guards keep nothing on disk (a fresh epoch per start), so `us` is all crypto and codec.

`before` is a seal with a state file: the same AES-CCM per frame, plus a state file written (temporary
file, fsync, rename, fsync of the folder) once per 256 frames sent and once per 16 accepted;
that write is timed here with the same write path, and its share per frame added. Bytes: that
seal's sync word was 4 bytes on 1 frame in 32, this one is 13 bytes (number bits, epoch, time) on 1
frame in 64 (and the first 3 of each epoch, and one after 30 s without any); `avg B` spreads
the sync words over all frames of a sender that sends at least one frame every 30 s.

The second table is wire format 2 (links of profiles native and packed): packets of 1 to 4
protected messages, sealed per message (each payload by LinkGuard, wire format 1's seal) and per
packet (one tag, PacketSeal), both through the link's packer and unpacker, measured in the same
run (interleaved). Bytes are averaged over a long run of packets sealed by fresh sides, sync
packets included (the first 3 of an epoch, then 1 in 64); `us` is seal + open of one packet
(the codec's cost, the same for both, is left out).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from codec_bench import interleaved_us, per_call_us, samples  # noqa: E402  (the codec benchmark's messages and timer)

from uwgen.codegen import generate  # noqa: E402
from uwgen.runtime.wire import envelope as env  # noqa: E402
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, Unpacker  # noqa: E402
from uwgen.runtime.stats import Counters  # noqa: E402
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD  # noqa: E402
from uwgen.security import wire  # noqa: E402
from uwgen.security.files import write_private  # noqa: E402
from uwgen.security.guard import SYNC_EVERY, GuardConfig, LinkGuard  # noqa: E402
from uwgen.security.packet_seal import PacketSeal  # noqa: E402

BEFORE_SYNC_BYTES, BEFORE_SYNC_EVERY = 4, 32     # the state-file seal's sync word
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
        one_before, per_packet = packet_table(pkg, msgs, number // 5, 6400 if not args.quick else 640)
        print(f"before: one fsync'd state-file write took {write_us:.0f} us here; one per "
              f"{BEFORE_SEND_BLOCK} frames sent and one per {BEFORE_RECV_BLOCK} accepted: "
              f"{before_disk:.1f} us per frame (it follows the disk). Now: no state write at all.")
        print(f"overhead goal: <= 10 B per frame; measured {wire.OVERHEAD} B, {wire.SYNC_OVERHEAD} B on "
              f"sync frames (1 in {SYNC_EVERY}): {wire.OVERHEAD + wire.SYNC_BYTES / SYNC_EVERY:.2f} B on "
              f"average (before: {wire.OVERHEAD + BEFORE_SYNC_BYTES / BEFORE_SYNC_EVERY:.2f} B); at "
              f"200 bit/s {8 * (wire.OVERHEAD + wire.SYNC_BYTES / SYNC_EVERY) / 200:.3f} s of air time "
              f"per frame (before {8 * (wire.OVERHEAD + BEFORE_SYNC_BYTES / BEFORE_SYNC_EVERY) / 200:.3f} s)")
        print(f"wire format 2 (measured above): {per_packet:.2f} B per protected packet on average, sync "
              f"packets included (goal <= 10 B; projected 8 + 13/64 = 8.20 B), whatever the number of "
              f"messages, against {one_before:.2f} B per message sealed alone; at 200 bit/s "
              f"{8 * per_packet / 200:.3f} s of air time per packet ({8 * one_before / 200:.3f} s per "
              f"message before)")


class Queue:
    """The scheduler side of a packer: every packet takes the same messages, protected at take
    time by `protect` (the per-message seal) or not (the per-packet seal)."""

    def __init__(self, payloads: list[bytes], protect=None):
        self.payloads, self.protect, self.left = payloads, protect, []

    def next_payload(self, now, budget=None, exclude=None, *, fill=False):
        if not self.left:
            return None
        p = self.left.pop(0)
        return 4, (self.protect(4, p) if self.protect is not None else p)


def per_message_pair(mode: str):
    """A sending and a receiving side sealing each message (wire format 1's per-payload seal on wire format 2 packets)."""
    tx, rx = guards(mode)
    queue = Queue([], tx.protect)
    packer = Packer(queue, sender=1, max_read_length=255, counters=Counters(PACKET_COUNTERS))
    unpacker = Unpacker(counters=Counters(PACKET_COUNTERS))

    def send(payloads):
        queue.left = list(payloads)
        return packer.next_packet(0.0)

    def receive(data):
        return [rx.unprotect(m) for m in unpacker.feed(data, 0.0)]
    return send, receive


def per_packet_pair(mode: str):
    """A sending and a receiving side sealing each packet once (PacketSeal)."""
    key = bytes(range(32))
    modes = {4: mode}
    tx = PacketSeal(key, GuardConfig("bench", 1, {2: "rx"}, modes))
    rx = PacketSeal(key, GuardConfig("bench", 2, {1: "tx"}, modes))
    queue = Queue([])
    packer = Packer(queue, sender=1, max_read_length=255, hooks=tx.hooks(),
                    counters=Counters(PACKET_COUNTERS))
    unpacker = Unpacker(rx.hooks(), counters=Counters(PACKET_COUNTERS))

    def send(payloads):
        queue.left = list(payloads)
        return packer.next_packet(0.0)

    def receive(data):
        return unpacker.feed(data, 0.0)
    return send, receive


def packet_table(pkg, msgs, number: int, packets: int) -> tuple[float, float]:
    """Prints the wire format 2 table; returns the mean overhead per protected packet (bytes)
    before and after, over every row."""
    names = ("geometry_msgs/msg/Twist", "std_msgs/msg/String", "geometry_msgs/msg/Pose",
             "geometry_msgs/msg/Twist")
    payloads = [pkg.codec(n).encode(msgs[n], [0, 4]) for n in names]
    print()
    print("wire format 2, one packet of k messages (id 4, encrypt): bytes on the air (frame "
          "included, sync packets averaged in) and seal + open time per packet")
    print(f"{'k':>2}{'unsealed B':>11}{'per-message B':>14}{'+B':>7}{'per-packet B':>13}{'+B':>6}"
          f"{'us per-message':>15}{'us per-packet':>14}{'x':>6}")
    extra_before, extra_after = [], []
    for k in range(1, len(payloads) + 1):
        batch = payloads[:k]
        plain = FRAME_OVERHEAD + len(env.Envelope(1, 0, tuple(env.from_v1(p) for p in batch)).encode())
        sizes = []
        for make in (per_message_pair, per_packet_pair):
            send, receive = make("encrypt")
            total = 0
            for _ in range(packets):                          # fresh sides: sync packets included
                data = send(batch)
                assert receive(data) == batch
                total += len(data) + FRAME_OVERHEAD
            sizes.append(total / packets)
        trips = []
        for make in (per_message_pair, per_packet_pair):
            send, receive = make("encrypt")
            trips.append(lambda send=send, receive=receive: receive(send(batch)))
        us_before, us_after = interleaved_us(trips, number)
        extra_before.append(sizes[0] - plain)
        extra_after.append(sizes[1] - plain)
        print(f"{k:>2}{plain:>11}{sizes[0]:>14.2f}{sizes[0] - plain:>7.2f}{sizes[1]:>13.2f}"
              f"{sizes[1] - plain:>6.2f}{us_before:>15.1f}{us_after:>14.1f}{us_after / us_before:>6.2f}")
    return extra_before[0], sum(extra_after) / len(extra_after)


if __name__ == "__main__":
    main()
