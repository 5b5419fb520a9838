"""Packet-aligned writes: a lost DESERT packet costs exactly the frames in it, never another one.

Each write of the Outbox becomes one DESERT packet (it is at most max_read_length bytes and
there is one write per period). The properties are checked on the Outbox alone (each write is a
packet, some are dropped) and through the emulator's core with random packet loss.
"""
from __future__ import annotations

from collections import deque

from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire.framing import SYNC, FrameDecoder, encode_frame
from uwgen.runtime.link.pacing import Outbox, Pacer


def writes_of(box: Outbox, frames: list[bytes]) -> list[tuple[bytes, list[int]]]:
    """Every write the outbox makes for `frames`, with the indexes of the frames that end in it."""
    q = deque(enumerate(frames))
    order: list[int] = []

    def pull():
        if not q:
            return None
        i, f = q.popleft()
        order.append(i)
        return f

    out, done, t = [], 0, 0.0
    while q or box.pending:
        batch = box.take(t, pull)
        if batch:
            box.sent(t)
            now_done = box.stats.frames_sent
            out.append((batch, order[done:now_done]))
            done = now_done
        t += 1.0
    return out


@st.composite
def packets_and_frames(draw, longest_fits: bool = True):
    mrl = draw(st.integers(8, 160))
    top = max(1, mrl - 4) if longest_fits else 255
    payloads = draw(st.lists(st.binary(min_size=1, max_size=min(top, 255)), min_size=1, max_size=40))
    return mrl, payloads


@settings(max_examples=300, deadline=None)
@given(packets_and_frames(), st.data())
def test_a_lost_packet_never_damages_a_frame_outside_it(case, data):
    mrl, payloads = case
    frames = [encode_frame(p) for p in payloads]
    writes = writes_of(Outbox(Pacer(mrl, 1.0)), frames)
    assert all(len(w) <= mrl and w.startswith(SYNC) for w, _ in writes)
    lost = data.draw(st.lists(st.booleans(), min_size=len(writes), max_size=len(writes)))
    stream = b"".join(w for (w, _), gone in zip(writes, lost) if not gone)
    expected = [payloads[i] for (_, idx), gone in zip(writes, lost) if not gone for i in idx]
    # Any content, 0x99 and 0x55 included: the stream that arrives is whole frames back to back.
    assert FrameDecoder().feed(stream) == expected


@settings(max_examples=200, deadline=None)
@given(packets_and_frames(longest_fits=False), st.data())
def test_every_frame_is_written_whole_or_in_writes_of_its_own(case, data):
    mrl, payloads = case
    frames = [encode_frame(p) for p in payloads]
    writes = writes_of(Outbox(Pacer(mrl, 1.0)), frames)
    # A cut frame's last piece is repeated at the start of the next write (its echo, written
    # only when it holds no 99 99): without the echoes, the writes are the frames.
    plain, last = [], b""
    for w, idx in writes:
        echo = last if last and SYNC not in last and len(last) < mrl and w.startswith(last) else b""
        plain.append((w[len(echo):], idx))
        last = w if not w.startswith(SYNC) else b""
    assert b"".join(w for w, _ in plain) == b"".join(frames)
    assert sum(len(idx) for _, idx in writes) == len(frames)
    for w, idx in plain:
        # A write holds whole frames, or one piece of a single frame longer than a packet.
        whole = b"".join(frames[i] for i in idx)
        assert len(w) <= mrl and (w == whole or len(idx) <= 1)


def test_cut_and_fill_lets_one_lost_packet_cost_a_frame_outside_it():
    # The reference the property above rules out: 40-byte frames cut at 64 bytes. Losing the
    # second packet also destroys the frame that started in the first one.
    frames = [encode_frame(bytes([65 + i]) * 36) for i in range(4)]
    writes = writes_of(Outbox(Pacer(64, 1.0), aligned=False), frames)
    stream = writes[0][0] + b"".join(w for w, _ in writes[2:])
    delivered = FrameDecoder().feed(stream)
    assert frames[1][3:-1] not in delivered and len(delivered) < 3


def scenario(per: float, seed: int) -> Scenario:
    return Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=64, per=per, seed=seed, bitrate=4800.0)


@settings(max_examples=12, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=60), min_size=30, max_size=60), st.integers(0, 10_000))
def test_through_the_emulator_with_random_loss_exactly_the_frames_of_arrived_packets_arrive(payloads, seed):
    sim = LinkSim(scenario(per=0.25, seed=seed), "a", "b")
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=1000))
    for p in payloads:
        sim.at(0.0, lambda p=p: sim.sender.offer(7, p))
    sim.run(len(payloads) * 0.25 + 3.0)
    arrived = b"".join(d.data for d in sim.packets)
    assert sim.core.counters("a")["bytes_in"] == sum(len(p) + 4 for p in payloads)
    assert all(d.data.startswith(SYNC) for d in sim.packets)
    # Every packet that arrived is whole frames, and all of them are delivered, in order.
    assert [p for _, p in sim.received] == FrameDecoder().feed(arrived)
    assert sum(len(p) + 4 for _, p in sim.received) == len(arrived)
    it = iter(payloads)
    assert all(any(p == q for q in it) for _, p in sim.received)       # sent ones, in order


def test_the_room_left_is_filled_with_frames_that_fit_and_the_held_one_goes_first():
    sim = LinkSim(scenario(per=0.0, seed=1), "a", "b")
    for key, prio in ((1, 10), (2, 5), (3, 0)):
        sim.sender.add_channel(key, LinkPolicy(queue="fifo", depth=9, priority=prio))
    for _ in range(2):
        sim.sender.offer(1, b"\x00\x01" + bytes(28))     # 34-byte frames
        sim.sender.offer(2, b"\x00\x02" + bytes(30))     # 36-byte frames
        sim.sender.offer(3, b"\x00\x03" + bytes(6))      # 12-byte frames
    sim.run(2.0)
    writes = [[p[1] for p in FrameDecoder().feed(d.data)] for d in sim.packets]
    # 1, then 2 (its turn: priorities share the link) held, 36 > 30 left, and the 12-byte ones
    # that fit; then the held 2 first, 1 held (34 > 28 left); then 1; then the last 2
    assert writes == [[1, 3, 3], [2], [1], [2]]
    assert [len(d.data) for d in sim.packets] == [58, 36, 34, 36]


@settings(max_examples=40, deadline=None)
@given(st.integers(16, 128), st.data())
def test_filling_with_frames_that_fit_keeps_writes_whole_and_each_channel_in_order(mrl, data):
    # Payloads of 5 .. mrl - 4 bytes: every frame fits a packet (longer ones are cut, see above).
    offers = data.draw(st.lists(st.tuples(st.integers(1, 3), st.integers(1, mrl - 8)), min_size=1, max_size=60))
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"), NodeSpec("b", position=(30, 0, 0), dest="a")],
                    period=0.2, max_read_length=mrl, bitrate=48_000.0)
    sim = LinkSim(scen, "a", "b")
    for key in (1, 2, 3):
        sim.sender.add_channel(key, LinkPolicy(queue="fifo", depth=100, priority=key % 2))
    for n, (key, size) in enumerate(offers):
        sim.sender.offer(key, bytes([0, key]) + n.to_bytes(2, "big") + bytes(size))
    sim.run(len(offers) * 0.25 + 1.0)
    assert all(len(d.data) <= mrl and d.data.startswith(SYNC) for d in sim.packets)
    for d in sim.packets:                            # each packet: whole frames
        assert sum(len(f) + 4 for f in FrameDecoder().feed(d.data)) == len(d.data)
    payloads = [p for _, p in sim.received]
    assert sorted(payloads) == sorted(bytes([0, k]) + n.to_bytes(2, "big") + bytes(s)
                                      for n, (k, s) in enumerate(offers))
    for key in (1, 2, 3):
        serials = [int.from_bytes(p[2:4], "big") for p in payloads if p[1] == key]
        assert serials == sorted(serials)
