"""A packet DESERT delivers twice (docs/wire-format.md section 15.7): on an unsealed link the
repeat is dropped whole, its messages, its report and its C items; a number too old to tell
is taken, never dropped on a guess."""
from __future__ import annotations

from uwgen.runtime.delivery.receiving import Receiving
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.link.hooks import PacketHooks, join_hooks
from uwgen.runtime.link.packets import PACKET_COUNTERS, Unpacker
from uwgen.runtime.stats import Counters
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.messages import Message

VEHICLE = 2


def receiver(extra: PacketHooks | None = None) -> tuple[Unpacker, Reliability]:
    rel = Reliability(1, period=0.2, reliable={}, max_ages={})
    hooks = rel.hooks() if extra is None else join_hooks(rel.hooks(), extra)
    return Unpacker(hooks, counters=Counters(PACKET_COUNTERS), name="surface"), rel


def packet(number: int, body: bytes = b"\x7d\x23", **parts) -> bytes:
    return envelope.Envelope(VEHICLE, number, (Message(0, 4, body),), **parts).encode()


def test_a_best_effort_message_in_a_packet_delivered_twice_is_delivered_once():
    unpacker, rel = receiver()
    first = unpacker.feed(packet(7), 1.0)
    again = unpacker.feed(packet(7), 1.5)
    assert first == [bytes((0, 4)) + b"\x7d\x23"]
    assert again == []
    assert unpacker.counters["repeated_packets"] == 1
    assert rel.counters["duplicate_packets"] == 1
    assert unpacker.counters["messages_received"] == 1


def test_the_next_packet_after_a_repeat_is_delivered():
    unpacker, _ = receiver()
    unpacker.feed(packet(7), 1.0)
    unpacker.feed(packet(7), 1.2)
    assert unpacker.feed(packet(8, b"\x01"), 1.4) == [bytes((0, 4, 1))]


def test_a_repeated_packet_never_reaches_the_hooks_after_reliability():
    heard = []
    mac = PacketHooks(received=lambda e, now: heard.append(e.number))
    unpacker, _ = receiver(mac)
    unpacker.feed(packet(7, control=bytes((0x22, 2))), 1.0)
    unpacker.feed(packet(7, control=bytes((0x22, 2))), 1.3)   # the same grant, repeated
    assert heard == [7]


def test_a_repeated_packets_report_is_not_taken_again():
    unpacker, rel = receiver()
    unpacker.feed(packet(7, ack=b"\x00"), 1.0)
    bad = rel.counters["bad_acks"]
    unpacker.feed(packet(7, ack=b"\x00"), 1.0)
    assert rel.counters["bad_acks"] == bad          # judged once, not twice


def test_a_number_too_far_below_the_window_is_delivered_not_dropped_as_a_repeat():
    unpacker, _ = receiver()
    unpacker.feed(packet(1000), 1.0)
    got = unpacker.feed(packet(800), 2.0)          # 200 below: past the 121 remembered
    assert got == [bytes((0, 4)) + b"\x7d\x23"]
    assert unpacker.counters["repeated_packets"] == 0


def test_receipts_count_a_number_below_the_window_too_old_and_take_it():
    r = Receiving()
    assert r.received(VEHICLE, b"e", 1000, 1.0, False)
    assert r.received(VEHICLE, b"e", 800, 2.0, False)
    assert not r.received(VEHICLE, b"e", 1000, 3.0, False)      # an exact repeat
    row = r.receipts[(VEHICLE, b"e")]
    assert (row.too_old, row.duplicates) == (1, 1)
