"""The reliability engine (uwgen.runtime.delivery.reliable): acks, loss, retransmission, delivery once."""
from __future__ import annotations

from pathlib import Path

import pytest

from uwgen.runtime.delivery.reliable import (AckError, ReliableLink, Report, RttEstimator, Sent,
                                    decode_reports, encode_reports, unwrap)

SURFACE, VEHICLE = 1, 2
EPOCH = b"\x01" * 6


def engine(me: int, rto: float = 6.0) -> ReliableLink:
    return ReliableLink(me, RttEstimator(rto, 1.0, 60.0, 0.5), ack_delay=2.0, bitmap_bytes=1)


def wire_format_15() -> str:
    text = (Path(__file__).resolve().parents[2] / "docs" / "wire-format.md").read_text()
    return text[text.index("## 15. Reliable delivery"):]


def test_a_report_has_the_bytes_of_the_worked_example():
    # wire-format 15.2: vehicle acks surface's packet 0x105, 0x104 missing, 0xFD..0x103 got.
    report = Report(SURFACE, 0x105, 0b0111_1111, 1, 1.3)
    assert encode_reports([report]).hex(" ") == "11 51 05 7f"
    assert "`11 51 05 7f`" in wire_format_15() and "`04 11 51 05 7f`" in wire_format_15()
    back = decode_reports(bytes.fromhex("11 51 05 7f"))[0]
    assert (back.peer, back.largest, back.bitmap, back.nbytes, back.delay) == (1, 0x105, 0x7F, 1, 1.25)
    got, missing = back.numbers()
    assert missing == [0x104] and got == [0x105, 0x103, 0x102, 0x101, 0x100, 0xFF, 0xFE, 0xFD]


@pytest.mark.parametrize("data", [b"\x11\x51", b"\x12\x51\x05\x7f"], ids=["head cut", "bitmap cut"])
def test_a_cut_report_is_refused(data):
    with pytest.raises(AckError):
        decode_reports(data)


def test_numbers_unwrap_across_4096():
    assert unwrap(2, 4094) == 4098 and unwrap(4094, 4098) == 4094 and unwrap(7, 7) == 7


def test_rto_follows_rfc_6298_from_the_measured_round_trip():
    rtt = RttEstimator(10.0, 1.0, 60.0, 0.5)
    rtt.sample(4.0)
    assert (rtt.srtt, rtt.rttvar, rtt.rto) == (4.0, 2.0, 12.0)       # 4 + 4 * 2
    rtt.sample(2.0)
    assert rtt.srtt == pytest.approx(3.75) and rtt.rttvar == pytest.approx(2.0)
    assert rtt.rto == pytest.approx(11.75)
    rtt.backoff()
    assert rtt.rto == pytest.approx(23.5)
    assert "RTO 12 s then 11.75 s" in wire_format_15() and "to 23.5 s" in wire_format_15()


def exchange(sender: ReliableLink, receiver: ReliableLink, numbers, arrives, now: float):
    """Packets `numbers` leave `sender`; those in `arrives` reach `receiver`."""
    for n in numbers:
        if n in arrives:
            assert receiver.received(sender.me, EPOCH, n % 4096, now, eliciting=True)


def test_a_lost_reliable_message_is_due_again_and_counted_lost():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(20, "req-a", deadline=30.0)], 0.0)
    s.sent(1, [Sent(20, "req-b", deadline=30.0), Sent(4, "cmd", None)], 0.5)
    s.sent(2, [Sent(4, "cmd2", None)], 1.0)
    exchange(s, r, [0, 1, 2], {0, 2}, 1.0)
    s.acked(r.ack_for(SURFACE, 3.0), 4.0)
    assert [m.ref for m in s.due(4.0)] == ["req-b"]
    assert s.due(4.0) == []                                         # handed out once
    assert (s.entry(20).delivered, s.entry(20).lost_on_link, s.entry(20).resent) == (1, 1, 1)
    assert (s.entry(4).delivered, s.entry(4).lost_on_link) == (1, 1)  # best effort: counted only
    assert s.rtt.samples == 1 and s.rtt.srtt == pytest.approx(1.0)    # 4.0 - 1.0 - 2.0 s held


def test_an_unacknowledged_packet_times_out_after_rto_plus_the_ack_delay_and_backs_off():
    s = engine(SURFACE, rto=6.0)                 # the peer may hold its ack 2 s (ack_delay)
    s.sent(0, [Sent(20, "req", deadline=30.0)], 0.0)
    assert s.due(7.9) == [] and s.next_timeout() == 8.0
    assert [m.ref for m in s.due(8.0)] == ["req"]
    assert s.rtt.rto == 12.0 and s.next_timeout() is None


def test_packets_no_ack_ever_named_are_forgotten_as_unacknowledged():
    s = engine(SURFACE)
    s.sent(0, [Sent(4, "a", None)], 0.0)
    s.sent(1, [Sent(4, "b", None), Sent(5, "c", None)], 0.1)
    s.sent(2, [Sent(5, "d", None)], 0.2)
    assert s.in_flight() == {4: 2, 5: 2}
    s.forget(2)
    assert s.in_flight() == {5: 1}
    assert (s.entry(4).unacknowledged, s.entry(5).unacknowledged) == (2, 1)


def test_a_message_past_its_deadline_is_not_sent_again():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(20, "req", deadline=5.0)], 0.0)
    s.sent(1, [Sent(4, "cmd", None)], 1.0)
    exchange(s, r, [0, 1], {1}, 1.0)
    s.acked(r.ack_for(SURFACE, 6.0), 6.0)
    assert s.due(6.0) == [] and s.entry(20).expired == 1 and s.entry(20).lost_on_link == 1


def test_a_late_ack_of_a_timed_out_packet_counts_a_spurious_retransmission():
    s, r = engine(SURFACE, rto=2.0), engine(VEHICLE)
    s.sent(0, [Sent(20, "req", deadline=30.0)], 0.0)
    assert len(s.due(4.0)) == 1
    exchange(s, r, [0], {0}, 4.5)
    s.acked(r.ack_for(SURFACE, 5.0), 5.0)
    assert s.spurious == 1 and s.entry(20).delivered == 1 and s.rtt.samples == 0   # Karn


def test_receiver_counts_duplicates_and_gaps_and_acks_across_the_wrap():
    r = engine(VEHICLE)
    for n in (4094, 4095, 1):            # 0 is lost
        assert r.received(SURFACE, EPOCH, n, 0.0, eliciting=False)
    assert not r.received(SURFACE, EPOCH, 4095, 0.1, eliciting=False)
    receipts = r.receipts[(SURFACE, EPOCH)]
    assert (receipts.duplicates, receipts.gaps) == (1, 1)
    report = decode_reports(r.ack_for(SURFACE, 0.2))[0]
    assert report.largest == 1 and report.numbers()[1][0] == 0      # 0 reported missing


def test_an_ack_goes_alone_only_when_the_peer_waits_for_one():
    r = engine(VEHICLE)
    r.received(SURFACE, EPOCH, 0, 0.0, eliciting=False)
    assert not r.ack_only_due(SURFACE, 10.0)
    assert r.ack_for(SURFACE, 10.0, any_news=False) is None
    r.received(SURFACE, EPOCH, 1, 10.0, eliciting=True)
    assert not r.ack_only_due(SURFACE, 11.9) and r.ack_only_due(SURFACE, 12.0)
    assert r.ack_for(SURFACE, 12.0) is not None and not r.ack_only_due(SURFACE, 20.0)


def test_a_new_epoch_starts_the_peers_state_over():
    r = engine(VEHICLE)
    r.received(SURFACE, EPOCH, 100, 0.0, eliciting=False)
    assert r.received(SURFACE, b"\x02" * 6, 100, 1.0, eliciting=False)    # not a duplicate
    assert list(r.receipts) == [(SURFACE, b"\x02" * 6)]


def test_a_reliable_message_is_delivered_once():
    r = engine(VEHICLE)
    assert r.deliver_once(SURFACE, EPOCH, 20, 7)
    assert not r.deliver_once(SURFACE, EPOCH, 20, 7)
    assert r.deliver_once(SURFACE, EPOCH, 21, 7)                      # another entry
    assert r.duplicates == {20: 1}


def test_an_ack_naming_a_packet_never_sent_is_counted_not_believed():
    s = engine(SURFACE)
    s.sent(0, [Sent(20, "req", deadline=30.0)], 0.0)
    s.acked(encode_reports([Report(SURFACE, 9)]), 1.0)
    s.acked(b"\x10\x00", 1.0)
    assert s.bad_acks == 2 and s.entry(20).delivered == 0


def test_command_timer_never_fires_before_the_answer_could_come_back():
    from uwgen.runtime.delivery.reliable import command_rtt
    plain = command_rtt(10.0, 0.2)
    assert plain.rto == 2.5                           # a quarter, without a MAC's figures
    far = command_rtt(10.0, 0.2, round_trip=4.9)      # 3.5 km: 2 x 2.33 s and two packets
    assert far.rto == 4.9
    far.sample(0.1)
    assert far.rto >= 4.9                             # never below the least round trip
    turns = command_rtt(10.0, 0.2, round_trip=0.5, turn_gap=3.0)
    assert turns.rto == 3.2                           # a period and the turn gap


@pytest.mark.parametrize("arrives, delivered, lost", [
    ({0, 1, 2}, 1, 0),          # head and tail arrived: the message did
    ({1, 2}, 0, 1),             # the head's packet lost
    ({0, 2}, 0, 1),             # the tail's packet lost: the head arrived alone
])
def test_a_cut_message_is_delivered_only_when_both_of_its_packets_arrived(arrives, delivered, lost):
    # wire-format.md 14.2: the message cut at packet 0's end is finished at packet 1's head
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(4, "whole", None), Sent(7, "cut", None)], 0.0)
    s.cut(0)
    s.sent(1, [Sent(4, "after", None)], 0.2)
    s.sent(2, [Sent(4, "last", None)], 0.4)
    exchange(s, r, [0, 1, 2], arrives, 1.0)
    s.acked(r.ack_for(SURFACE, 3.0), 4.0)
    assert (s.entry(7).sent, s.entry(7).delivered, s.entry(7).lost_on_link) == (1, delivered, lost)
    assert s.entry(4).delivered == len(arrives) and s.in_flight() == {}


def test_a_message_moved_whole_to_the_next_packet_shares_that_packets_fate():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(4, "a", None), Sent(7, "moved", None)], 0.0)
    s.cut(0, moved=True)
    s.sent(1, [Sent(4, "b", None)], 0.2)
    s.sent(2, [Sent(4, "c", None)], 0.4)
    exchange(s, r, [0, 1, 2], {1, 2}, 1.0)          # packet 0 lost, packet 1 (the message) arrived
    s.acked(r.ack_for(SURFACE, 3.0), 4.0)
    assert (s.entry(7).sent, s.entry(7).delivered, s.entry(7).lost_on_link) == (1, 1, 0)


def test_a_copy_sent_again_carries_the_messages_age_now_not_its_first():
    # a reliable message with a max age, published at 0 and first sent at 0.5 s (age item
    # 0.5 s), is lost; its copy at 4.9 s must say 4.75 s (quarter seconds, rounded down), or
    # the receiver would judge it 4.4 s younger than it is
    from uwgen.runtime.delivery.reliability import Reliability
    from uwgen.runtime.wire.envelope import from_v1
    from uwgen.runtime.wire.heads import decode_age
    r = Reliability(1, period=0.2, reliable={9: 5.0}, max_ages={9: 5.0})
    stamped = r.stamp(9, bytes((0, 9, 0xF5)), 0.0, 0.5)
    assert decode_age(from_v1(stamped).body, 1)[0] == 0.5
    r.sent(0, [(9, stamped)], 0.5)
    key, copy = r.resend(4.9, 64)                  # no report came: the timer gives it back
    m = from_v1(copy)
    assert key == 9 and m.body[0] == from_v1(stamped).body[0]          # the same N
    assert decode_age(m.body, 1)[0] == 4.75 and m.body[-1] == 0xF5


def test_a_reassembled_message_is_judged_by_its_first_fragments_packet_time():
    # its age item was written with its first fragment: judged by the T of the last
    # fragment's packet it would look younger by all the time its fragments took
    from uwgen.runtime.delivery.freshness import stamp
    from uwgen.runtime.delivery.reliability import Reliability
    from uwgen.runtime.wire import envelope as env
    from uwgen.runtime.wire.heads import encode_age

    class Wall:
        t = 1_790_000_000.0

        def now(self):
            return self.t
    wall = Wall()
    whole = bytes((0, 9)) + encode_age(0.0) + b"\xf5"            # max age 30 s, age item 0

    def receive(transfer):
        r = Reliability(2, period=0.2, reliable={}, max_ages={9: 30.0}, wall=wall)
        first = env.Message(env.FRAGMENT, 0, bytes((7, 0, 2)) + b"ab")
        last = env.Message(env.FRAGMENT, 0, bytes((7, 1, 2)) + b"cd")
        r.received(env.Envelope(1, 0, (first,), time=stamp(wall.t - 40.0)), 0.0)  # 40 s ago
        r.received(env.Envelope(1, 1, (last,), time=stamp(wall.t - 0.5)), 0.0)
        return r.admit(whole, 0.0) if transfer is None else r.admit(whole, 0.0, transfer=transfer)
    assert receive(None) == bytes((0, 9, 0xF5))    # by the last packet's T: 0.5 s old, taken
    assert receive(7) is None                      # by the first's: 40 s, past its 30 s
