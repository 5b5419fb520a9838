"""State kept per peer when one side hears three vehicles on one channel (a fleet): each
vehicle's packet numbers, duplicates and reliable messages are its own, and a surface packet
is acknowledged by each vehicle it is for, not by whichever vehicle answers first."""
from __future__ import annotations

from uwgen.runtime.delivery.reliable import (REPORT_KEY, ReliableLink, Report, RttEstimator, Sent,
                                             encode_reports)

SURFACE, AUV1, AUV2, AUV3 = 1, 2, 3, 4
EPOCH = b"\x00" * 8


def engine(me: int) -> ReliableLink:
    return ReliableLink(me, RttEstimator(2.0, 0.2, 60.0, 0.2), ack_delay=1.0)


def report(about: int, largest: int, bitmap: int = 0, nbytes: int = 0) -> bytes:
    return encode_reports([Report(about, largest, bitmap, nbytes)])


def test_three_vehicles_with_the_same_packet_numbers_are_three_records():
    surface = engine(SURFACE)
    for vehicle in (AUV1, AUV2, AUV3):
        for number in (0, 1, 2):
            assert surface.received(vehicle, EPOCH, number, 0.0, eliciting=False)
    # a repeat is a repeat of that vehicle only
    assert not surface.received(AUV2, EPOCH, 1, 0.1, eliciting=False)
    assert surface.received(AUV3, EPOCH, 3, 0.1, eliciting=False)
    assert {p: r.largest for (p, _), r in surface.receipts.items()} == {AUV1: 2, AUV2: 2, AUV3: 3}
    assert {p: r.duplicates for (p, _), r in surface.receipts.items()} == {AUV1: 0, AUV2: 1, AUV3: 0}
    # each vehicle gets its own report
    assert surface.ack_for(AUV1, 0.2) != surface.ack_for(AUV3, 0.2)


def test_a_reliable_message_is_delivered_once_per_vehicle_not_once_per_fleet():
    surface = engine(SURFACE)
    assert [surface.deliver_once(v, EPOCH, 11, 7) for v in (AUV1, AUV2, AUV3)] == [True] * 3
    assert not surface.deliver_once(AUV2, EPOCH, 11, 7)
    assert surface.duplicates == {11: 1}


def test_a_restarted_vehicle_forgets_its_own_numbers_only():
    surface = engine(SURFACE)
    for vehicle in (AUV1, AUV2):
        surface.received(vehicle, EPOCH, 40, 0.0, eliciting=False)
    assert surface.received(AUV1, b"\x01" * 8, 0, 1.0, eliciting=False)      # new epoch
    assert not surface.received(AUV2, EPOCH, 40, 1.0, eliciting=False)      # still known
    assert sorted(p for p, _ in surface.receipts) == [AUV1, AUV2]


def test_a_packet_for_two_vehicles_is_delivered_once_both_acknowledged_it():
    surface = engine(SURFACE)
    surface.sent(0, [Sent(10, "cmd auv1", 5.0), Sent(20, "cmd auv2", 5.0)], 0.0, to={AUV1, AUV2})
    surface.acked(report(SURFACE, 0), 1.0, reporter=AUV3)      # not for auv3: says nothing
    surface.acked(report(SURFACE, 0), 1.0, reporter=AUV1)
    assert 0 in surface.outstanding and surface.ledger[10].delivered == 0
    surface.acked(report(SURFACE, 0), 1.2, reporter=AUV2)
    assert 0 not in surface.outstanding
    assert (surface.ledger[10].delivered, surface.ledger[20].delivered) == (1, 1)


def test_a_packet_one_vehicle_missed_is_lost_even_when_another_acknowledged_it():
    surface = engine(SURFACE)
    surface.sent(0, [Sent(20, "cmd auv2", 9.0)], 0.0, to={AUV2})
    surface.sent(1, [Sent(20, "cmd auv2 again", 9.0)], 0.2, to={AUV2})
    # auv1 overheard both and acknowledges them: that is not auv2's word
    surface.acked(report(SURFACE, 1, bitmap=0b1, nbytes=1), 1.0, reporter=AUV1)
    assert set(surface.outstanding) == {0, 1}
    # auv2 got packet 1, not packet 0: 0 is lost and its reliable message handed back
    surface.acked(report(SURFACE, 1, bitmap=0b0, nbytes=1), 1.1, reporter=AUV2)
    assert surface.ledger[20].lost_on_link == 1 and surface.ledger[20].delivered == 1
    assert [m.ref for m in surface.due(1.1)] == ["cmd auv2"]


def test_a_report_about_a_vehicle_is_confirmed_by_that_vehicle_only():
    surface = engine(SURFACE)
    named = (AUV1, EPOCH, 12)
    surface.sent(0, [Sent(REPORT_KEY, named, None)], 0.0, to={AUV1})
    surface.acked(report(SURFACE, 0), 0.5, reporter=AUV2)
    assert surface.confirmed == []
    surface.acked(report(SURFACE, 0), 0.6, reporter=AUV1)
    assert surface.confirmed == [named]


def test_without_destinations_the_first_report_settles_a_packet_as_between_two_sides():
    surface = engine(SURFACE)
    surface.sent(0, [Sent(10, "cmd", 5.0)], 0.0)
    surface.acked(report(SURFACE, 0), 1.0, reporter=AUV1)
    assert surface.outstanding == {} and surface.ledger[10].delivered == 1
