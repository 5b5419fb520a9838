"""Pacing (sans-IO, ManualClock): one write of at most max_read_length bytes per period, pulled."""
from __future__ import annotations

from collections import deque

import pytest

from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.framing import FrameDecoder, encode_frame
from uwgen.runtime.link.pacing import Outbox, Pacer
from uwgen.runtime.link.scheduler import DROP_REASONS, LinkScheduler


def frames_from(*payloads: bytes):
    q = deque(encode_frame(p) for p in payloads)
    pulled = []

    def pull():
        if not q:
            return None
        pulled.append(q[0])
        return q.popleft()
    return pull, pulled


def test_pacer_allows_first_write_at_once_then_one_per_period():
    p = Pacer(64, 0.2)
    assert p.may_write(0.0)
    p.wrote(0.0)
    assert not p.may_write(0.19)
    assert p.may_write(0.2)


@pytest.mark.parametrize("max_bytes, period", [(0, 1.0), (64, 0.0), (64, -1)])
def test_pacer_refuses_nonsense_config(max_bytes, period):
    with pytest.raises(ValueError):
        Pacer(max_bytes, period)


def test_small_frames_share_one_write():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"a" * 10, b"b" * 10, b"c" * 10)
    batch = box.take(0.0, pull)
    assert batch == encode_frame(b"a" * 10) + encode_frame(b"b" * 10) + encode_frame(b"c" * 10)
    box.sent(0.0)
    assert box.stats.frames_sent == 3 and box.stats.writes == 1


def run_box(box, pull, seconds=2.0, step=0.05):
    """Every write the outbox makes in `seconds`, as (time, bytes)."""
    writes = []
    for i in range(int(seconds / step)):
        t = round(i * step, 6)
        batch = box.take(t, pull)
        if batch:
            box.sent(t)
            writes.append((t, batch))
    return writes


def test_a_frame_that_does_not_fit_waits_whole_for_the_next_write():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"a" * 30, b"b" * 30, b"c" * 5)     # 34-byte frames: one per write
    writes = run_box(box, pull)
    assert [w for _, w in writes] == [encode_frame(b"a" * 30), encode_frame(b"b" * 30) + encode_frame(b"c" * 5)]
    assert writes[1][0] - writes[0][0] >= 0.2
    assert box.stats.frames_sent == 3


def test_a_frame_longer_than_a_packet_is_cut_into_writes_of_its_own():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"w" * 5, b"x" * 100, b"y" * 5)
    writes = [w for _, w in run_box(box, pull)]
    x = encode_frame(b"x" * 100)
    # The cut frame's last piece is repeated at the start of the next write (its echo).
    assert writes == [encode_frame(b"w" * 5), x[:64], x[64:], x[64:] + encode_frame(b"y" * 5)]
    assert box.stats.frames_sent == 3


def strict_rmw_desert(stream: bytes) -> list[bytes]:
    """rmw_desert's receiver as observed (benchmarks/rmw_peer_bench.py): after `99 99 LEN` it
    takes LEN + 1 bytes whatever they hold; delivered when the last is 0x55."""
    out, i = [], 0
    while (i := stream.find(b"\x99\x99", i)) >= 0 and i + 3 <= len(stream):
        n = stream[i + 2]
        if i + 4 + n > len(stream):
            break
        if n and stream[i + 3 + n] == 0x55:
            out.append(stream[i + 3:i + 3 + n])
        i += 4 + n
    return out


@pytest.mark.parametrize("lost", [None, 1, 2, 3])
def test_the_echoed_tail_repairs_a_lost_tail_and_is_skipped_otherwise(lost):
    box = Outbox(Pacer(64, 0.2))
    beacon = bytes(range(1, 24)) * 4                    # 92 bytes, no 99 99: two packets
    pull, _ = frames_from(b"w" * 5, beacon, b"y" * 5, b"z" * 5)
    writes = [w for _, w in run_box(box, pull)]
    assert len(writes) == 4 and writes[3].startswith(writes[2])
    stream = b"".join(w for k, w in enumerate(writes) if k != lost)
    want = {None: [b"w" * 5, beacon, b"y" * 5, b"z" * 5],     # the echo is skipped
            1: [b"w" * 5, b"y" * 5, b"z" * 5],                # head lost: tail and echo skipped
            2: [b"w" * 5, beacon, b"y" * 5, b"z" * 5],        # tail lost: the echo completes it
            3: [b"w" * 5, beacon]}[lost]                      # the echo's packet lost: as always
    assert strict_rmw_desert(stream) == want
    assert FrameDecoder().feed(stream) == want
    # Without the echo a lost tail takes the next packet's frames with it.
    plain = Outbox(Pacer(64, 0.2), echo=False)
    pull, _ = frames_from(b"w" * 5, beacon, b"y" * 5, b"z" * 5)
    writes = [w for _, w in run_box(plain, pull)]
    assert strict_rmw_desert(writes[0] + writes[1] + writes[3]) == [b"w" * 5]


def test_a_tail_holding_a_start_is_not_echoed():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"x" * 70 + b"\x99\x99" + b"x" * 10, b"y" * 5)
    writes = [w for _, w in run_box(box, pull)]
    assert writes[-1] == encode_frame(b"y" * 5)


def test_cut_and_fill_mode_cuts_the_last_frame_and_fills_every_write():
    box = Outbox(Pacer(64, 0.2), aligned=False)
    pull, _ = frames_from(b"x" * 100, b"y" * 5)
    writes = [w for _, w in run_box(box, pull)]
    assert b"".join(writes) == encode_frame(b"x" * 100) + encode_frame(b"y" * 5)
    assert [len(w) for w in writes] == [64, 104 + 9 - 64]
    assert box.stats.frames_sent == 2


def test_nothing_is_pulled_before_the_pacer_allows():
    box = Outbox(Pacer(64, 0.2))
    pull, pulled = frames_from(b"a" * 50, b"b" * 50, b"c")
    box.take(0.0, pull)
    box.sent(0.0)
    assert len(pulled) == 2          # the second only because room was left in the first write
    assert box.take(0.1, pull) == b""
    assert len(pulled) == 2


def test_pull_stops_when_the_write_is_full():
    box = Outbox(Pacer(16, 1.0))
    pull, pulled = frames_from(*[b"z" * 4] * 10)      # 8-byte frames
    assert len(box.take(0.0, pull)) == 16
    assert len(pulled) == 2


def test_nothing_to_send_costs_no_period():
    box = Outbox(Pacer(64, 0.2))
    assert box.take(0.0, lambda: None) == b""
    pull, _ = frames_from(b"late")
    assert box.take(0.01, pull) == encode_frame(b"late")


def test_abandon_counts_the_cut_frame_and_forgets_it():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"x" * 100, b"y")
    box.take(0.0, pull)
    box.sent(0.0)
    assert box.pending
    assert box.abandon() == 1
    assert not box.pending and box.stats.frames_abandoned == 1
    assert box.take(0.2, pull) == encode_frame(b"y")        # the next frame starts clean


def test_a_held_whole_frame_survives_a_disconnect_and_goes_first():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"a" * 40, b"b" * 40)
    assert box.take(0.0, pull) == encode_frame(b"a" * 40)
    assert box.abandon() == 1                                 # the written-and-failed one only
    assert box.pending
    assert box.take(0.2, pull) == encode_frame(b"b" * 40)


def test_failed_write_abandons_every_frame_in_it():
    box = Outbox(Pacer(64, 0.2))
    pull, _ = frames_from(b"a" * 10, b"b" * 40)
    assert len(box.take(0.0, pull)) == 58
    assert box.abandon() == 2
    assert box.stats.frames_sent == 0 and box.stats.bytes_sent == 0


class FakeDesert:
    """DESERT's side of the socket: queues what it reads as packets of at most max_read_length
    bytes, and sends one packet per period at its own phase (unrelated to ours)."""

    def __init__(self, config: LinkConfig, phase: float):
        self.config = config
        self.next_tick = phase
        self.queue: deque[bytes] = deque()
        self.delivered = bytearray()
        self.max_queued = 0

        self.waits: list[float] = []        # how long each packet waited in DESERT

    def write(self, data: bytes, now: float) -> None:
        m = self.config.max_read_length
        self.queue.extend((data[i:i + m], now) for i in range(0, len(data), m))
        self.max_queued = max(self.max_queued, self.queued_bytes)

    @property
    def queued_bytes(self) -> int:
        return sum(len(d) for d, _ in self.queue)

    def advance(self, now: float) -> list[bytes]:
        sent = []
        while now >= self.next_tick:
            if self.queue:
                data, t = self.queue.popleft()
                sent.append(data)
                self.waits.append(self.next_tick - t)
            self.next_tick += self.config.period
        return sent


def run_link(config, writer, seconds, step=0.005, phase=0.137, margin=None):
    """Writer -> scheduler -> outbox -> FakeDesert, on a ManualClock; yields DESERT's packets."""
    clock = ManualClock()
    sched = LinkScheduler(clock)
    box = Outbox(Pacer.for_link(config) if margin is None else Pacer.for_link(config, margin))
    desert = FakeDesert(config, phase)
    decoder = FrameDecoder()
    arrivals = []

    def pull():
        picked = sched.next_payload(clock.now())
        return None if picked is None else encode_frame(picked[1])

    writer.setup(sched)
    steps = int(seconds / step)
    for i in range(steps):
        clock.set(i * step)
        writer.tick(sched, clock.now())
        batch = box.take(clock.now(), pull)
        if batch:
            desert.write(batch, clock.now())
            box.sent(clock.now())
        for packet in desert.advance(clock.now()):
            desert.delivered += packet
            arrivals += [(clock.now(), p) for p in decoder.feed(packet)]
    return sched, box, desert, arrivals


class Flood:
    """Ten times what the link carries: 40-byte messages, 80 per second, on a fifo channel."""

    def __init__(self, rate=80.0, size=40):
        self.interval, self.size, self.next, self.n = 1 / rate, size, 0.0, 0

    def setup(self, sched):
        sched.add_channel(7, LinkPolicy(queue="fifo", depth=16, ttl=5.0))

    def tick(self, sched, now):
        while now >= self.next:
            self.n += 1
            sched.offer(7, b"\x00\x07" + self.n.to_bytes(4, "big") + bytes(self.size - 6))
            self.next += self.interval


def test_writer_ten_times_faster_than_link_leaves_at_most_one_packet_in_desert():
    config = LinkConfig(max_read_length=64, period=0.2)
    flood = Flood()
    assert flood.size * 80 >= 10 * config.bytes_per_second
    sched, box, desert, arrivals = run_link(config, flood, seconds=30)
    assert desert.max_queued <= config.max_read_length         # about one period of data, ever
    # The link is used, not starved: at least 90 % of the periods carried a packet with as many
    # whole 44-byte frames as fit (one: packet-aligned writes never cut a frame to fill a packet).
    frame = flood.size + 4
    assert len(desert.delivered) >= 0.9 * 30 / config.period * (config.max_read_length // frame) * frame
    # Everything that did not fit was dropped by policy, and every message is accounted for.
    c = sched.stats()[7]
    assert c["offered"] == c["sent"] + sum(c[r] for r in DROP_REASONS) + c["queued"]
    assert c["overflow"] + c["expired"] > 0.8 * c["offered"]
    serials = [int.from_bytes(p[2:6], "big") for _, p in arrivals]
    assert serials == sorted(set(serials))


class Commands:
    """cmd_vel: 22-byte Twist payloads at 10 Hz on a latest channel (the thesis' teleoperation)."""

    def __init__(self):
        self.next, self.n, self.offered_at = 0.0, 0, {}

    def setup(self, sched):
        sched.add_channel(4, LinkPolicy(queue="latest", rate=5, ttl=1.0, priority=10))

    def tick(self, sched, now):
        while now >= self.next:
            self.n += 1
            self.offered_at[self.n] = now
            sched.offer(4, b"\x00\x04" + self.n.to_bytes(4, "big") + bytes(16))
            self.next += 0.1


class Both:
    def __init__(self, *writers):
        self.writers = writers

    def setup(self, sched):
        for w in self.writers:
            w.setup(sched)

    def tick(self, sched, now):
        for w in self.writers:
            w.tick(sched, now)


def test_command_latency_stays_bounded_under_overload():
    config = LinkConfig(max_read_length=64, period=0.2)
    cmds = Commands()
    _, _, desert, arrivals = run_link(config, Both(cmds, Flood()), seconds=30)
    latencies = [t - cmds.offered_at[int.from_bytes(p[2:6], "big")] for t, p in arrivals if p[1] == 4]
    assert len(latencies) >= 0.8 * 30 * 5 / 2                   # most rate-allowed commands arrive
    # Time in our queue (< one rate interval) + pacer wait + DESERT's tick: about two periods.
    assert max(latencies) <= 2 * config.period + 0.05
    assert desert.max_queued <= config.max_read_length


def test_pace_margin_keeps_writes_from_sticking_just_after_desert_ticks():
    # DESERT ticks 1 ms before each of our writes would land: without a margin every packet waits
    # a whole period in DESERT; a 5 % slower pace slides through DESERT's phase (half a period on
    # average).
    # (Binary fractions keep the simulated times exact, so "no margin" really has a fixed phase.)
    config = LinkConfig(max_read_length=64, period=0.25)
    step = 1 / 256
    *_, stuck, _ = run_link(config, Flood(), seconds=30, step=step, phase=0.25 - step, margin=0.0)
    *_, sliding, _ = run_link(config, Flood(), seconds=30, step=step, phase=0.25 - step, margin=0.05)
    mean = lambda xs: sum(xs) / len(xs)
    assert mean(stuck.waits) > 0.24
    assert 0.09 < mean(sliding.waits) < 0.16
    assert stuck.max_queued <= 64 and sliding.max_queued <= 64


def test_pacer_margin_stretches_the_interval():
    p = Pacer(64, 0.2, margin=0.05)
    p.wrote(1.0)
    assert not p.may_write(1.2) and p.may_write(1.21)
    with pytest.raises(ValueError):
        Pacer(64, 0.2, margin=-0.1)


def test_a_write_late_by_less_than_the_margin_keeps_the_grid():
    # The connection's thread wakes a little after the write was due: the next write is due one
    # interval after the due time, not after the late write (the margin is the only loss)...
    p = Pacer(64, 0.2, margin=0.05)
    p.wrote(1.0)
    assert p.next_write_at == pytest.approx(1.21)
    p.wrote(1.215)
    assert p.next_write_at == pytest.approx(1.42)
    assert p.next_write_at - 1.215 >= 0.2                   # never two writes within a period
    # ... and a write long after it was due (an idle link) starts a new grid.
    p.wrote(1.6)
    assert p.next_write_at == pytest.approx(1.81)


def test_bitrate_stretches_the_interval_to_the_packets_air_time():
    # 64 + 4 header bytes at 4800 bit/s take 0.113 s on the air: more than a 0.05 s period.
    p = Pacer(64, 0.05, bitrate=4800)
    p.wrote(0.0, 64)
    assert p.next_write_at == pytest.approx(68 * 8 / 4800)
    p.wrote(1.0, 2)                         # a short packet: the period is the limit again
    assert p.next_write_at == pytest.approx(1.05)
