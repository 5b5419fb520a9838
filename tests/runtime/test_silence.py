"""A peer's packet with no report where it would have reported (docs/wire-format.md section
15.2, "Silence"; uwgen.runtime.delivery.silence): under turns, an eliciting packet of ours
that had settled before the peer's packet was built, with no packet of the peer lost since
ours left, never reached it."""
from __future__ import annotations

from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.wire import envelope as env

CALL, TOPIC = 20, 4
REQUEST = bytes((2, CALL, 7)) + bytes(12)
VEHICLE = 2


def surface(settled_by=lambda peer, now: 1.0):
    """The leader's reliability, its request sent in packet 0 after it heard the vehicle's
    packet 0; `settled_by` as its MAC says (default: all it wrote until 1.0 s)."""
    told: list = []
    s = Reliability(1, period=0.2, reliable={}, max_ages={CALL: 12.0}, max_read_length=64,
                    commands=frozenset({CALL}), settled_by=settled_by)
    s.on_fate = lambda key, payload, arrived: told.append((key, payload, arrived))
    s.received(env.Envelope(sender=VEHICLE, number=0), 0.0)
    s.carrying([(CALL, REQUEST)], 0.1)
    s.sent(0, [(CALL, s.stamp(CALL, REQUEST, 0.1, 0.1))], 0.1)
    return s, told


def test_a_request_is_told_lost_when_the_peers_next_packet_comes_without_a_report():
    s, told = surface()
    s.received(env.Envelope(sender=VEHICLE, number=1), 1.5)     # its turn: no A part at all
    assert told == [(CALL, REQUEST, False)]
    assert s.stats()["reliability"]["lost_by_silence"] == 1
    s.received(env.Envelope(sender=VEHICLE, number=2), 1.7)     # told once
    assert told == [(CALL, REQUEST, False)]


def test_a_peer_packet_lost_since_ours_left_may_have_carried_the_report():
    s, told = surface()
    s.received(env.Envelope(sender=VEHICLE, number=2), 1.5)     # its packet 1 was lost
    assert told == [] and s.stats()["reliability"]["lost_by_silence"] == 0


def test_a_peer_packet_built_before_ours_had_settled_says_nothing():
    s, told = surface(settled_by=lambda peer, now: 0.05)        # ours left at 0.1: after
    s.received(env.Envelope(sender=VEHICLE, number=1), 1.5)
    assert told == []


def test_without_turns_silence_says_nothing():
    s, told = surface(settled_by=lambda peer, now: None)         # TDMA, no MAC
    s.received(env.Envelope(sender=VEHICLE, number=1), 1.5)
    assert told == []


def test_a_packet_of_best_effort_topics_alone_is_not_taken_as_lost():
    s, told = surface()
    s.carrying([(TOPIC, b"\x00\x04t")], 0.3)
    s.sent(1, [(TOPIC, b"\x00\x04t")], 0.3)
    s.received(env.Envelope(sender=VEHICLE, number=1), 1.5)
    assert s.stats()["reliability"]["lost_by_silence"] == 1     # packet 0 only, not 1


def test_the_peer_that_got_a_request_reports_on_its_next_packet_so_silence_means_lost():
    # the premise, end to end: a vehicle given the request names it on the packet it builds
    s, told = surface()
    vehicle = Reliability(VEHICLE, period=0.2, reliable={}, max_ages={CALL: 12.0},
                          max_read_length=64, commands=frozenset({CALL}))
    vehicle.received(env.Envelope(sender=1, number=0, messages=[env.from_v1(REQUEST)]), 0.8)
    vehicle.carrying([], 1.2, fresh=False)
    parts = vehicle.parts(1.2)
    s.received(env.Envelope(sender=VEHICLE, number=1, ack=parts.get("ack")), 1.5)
    assert told == [(CALL, REQUEST, True)]
