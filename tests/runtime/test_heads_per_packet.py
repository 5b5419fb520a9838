"""Heads sized per packet (docs/seams.md section 9): T and the A part take room only in the
packets that carry them, and a packet never exceeds max_read_length."""
from __future__ import annotations

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, message_measure
from uwgen.runtime.link.scheduler import LinkScheduler
from uwgen.runtime.stats import Counters
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import SHORT_OVERHEAD as OVERHEAD   # the short frame's LEN


def link(max_ages: dict[int, float], reliable=None, mrl: int = 64):
    clock = ManualClock()
    rel = Reliability(1, period=0.2, reliable=reliable or {}, max_ages=max_ages,
                      wall=clock, max_read_length=mrl)
    hooks = rel.hooks()
    s = LinkScheduler(clock, measure=message_measure, stamp=hooks.stamp,
                      overhead=hooks.head_room)
    for key in (4, 5):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=100))
    return rel, s, Packer(s, sender=1, max_read_length=mrl, hooks=hooks,
                          counters=Counters(PACKET_COUNTERS))


def fill(s: LinkScheduler, key: int, n: int = 40) -> None:
    for i in range(n):
        s.offer(key, bytes((0, key)) + i.to_bytes(4, "big"))


def test_a_packet_without_timed_messages_or_a_due_ack_keeps_no_room_for_them():
    _, s, packer = link(max_ages={})
    fill(s, 4)
    data = packer.next_packet(0.0)
    e = envelope.decode(data)
    # 64 - 1 (frame) - 3 (P, W) = 60 bytes: a run of 14 4-byte bodies (3 bytes of head)
    assert len(e.messages) == 14 and e.time is None and e.ack is None
    assert len(data) + OVERHEAD == 63             # 11 messages while 9 bytes were kept free


def test_a_timed_message_brings_its_t_and_the_packet_still_fits():
    _, s, packer = link(max_ages={5: 30.0})
    fill(s, 4)
    fill(s, 5)
    for _ in range(8):
        data = packer.next_packet(0.0)
        e = envelope.decode(data)
        assert len(data) + OVERHEAD <= 64
        timed = any(m.id == 5 for m in e.messages)
        assert (e.time is not None) == timed


def test_an_ack_that_is_due_gets_its_room_and_the_packet_still_fits():
    rel, s, packer = link(max_ages={}, reliable={4: 30.0})
    # the peer (sender 2) sent a packet with a message of a reliable entry: it waits for an ack
    peer = envelope.Envelope(2, 7, (envelope.Message(0, 4, b"\x01\x02"),))
    rel.received(peer, 0.0)
    assert rel.next_overhead(0.0) > 0
    fill(s, 5)
    data = packer.next_packet(0.0)
    e = envelope.decode(data)
    assert e.ack and len(data) + OVERHEAD <= 64
    assert rel.next_overhead(0.1) == 0          # reported: nothing due on the next packet
    e = envelope.decode(packer.next_packet(0.1))
    assert e.ack is None and len(e.messages) == 14
