"""A command's fate (docs/wire-format.md section 15.6, "A command's fate"): the link tells the
bridge, from the peer's reports, which of its command messages arrived and which were lost,
once each, as the bridge offered them; a packet carrying a command asks for a report."""
from __future__ import annotations

from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.delivery.reliable import ReliableLink, RttEstimator, Sent
from uwgen.runtime.delivery.reports import Report, encode_reports
from uwgen.runtime.wire import envelope as env

CALL, TOPIC = 20, 4
REQUEST = bytes((2, CALL, 7)) + bytes(12)
OTHER = bytes((2, CALL, 8)) + bytes(12)


def engine() -> ReliableLink:
    link = ReliableLink(1, RttEstimator(2.0, 0.2, 60.0, 0.2), ack_delay=1.0)
    link.told.watched = frozenset({CALL})
    return link


def report(largest: int, bitmap: int, nbytes: int = 1) -> bytes:
    """An A part's reports about sender 1's packets."""
    return encode_reports([Report(1, largest, bitmap, nbytes)])


def test_a_report_tells_each_command_message_arrived_or_lost_and_nothing_of_topics():
    link = engine()
    link.sent(0, [Sent(CALL, REQUEST, None), Sent(TOPIC, b"topic", None)], 0.0)
    link.sent(1, [Sent(CALL, OTHER, None)], 0.2)
    link.acked(report(1, 0b0000_0000), 1.0)           # 1 arrived, 0 did not
    assert sorted(link.told.fates) == [(CALL, REQUEST, False), (CALL, OTHER, True)]


def test_a_packet_overtaken_under_turns_is_told_lost_once():
    link = engine()
    link.sent(0, [Sent(TOPIC, b"t", None)], 0.0)
    link.sent(1, [Sent(CALL, REQUEST, None)], 0.2)    # its turn's last packet
    link.acked(report(0, 0, 0), 1.0, settled_by=0.5)  # built after 1 arrived or was lost
    assert link.told.fates == [(CALL, REQUEST, False)]
    link.told.fates.clear()
    link.sent(2, [Sent(TOPIC, b"t", None)], 2.0)
    link.acked(report(2, 0b0000_0000), 3.0)           # names 1 missing: already told
    assert link.told.fates == []


def test_a_cut_command_is_told_with_the_packet_of_its_tail():
    link = engine()
    link.sent(0, [Sent(CALL, REQUEST, None)], 0.0)
    link.cut(0)                                       # its tail rides packet 1
    link.sent(1, [Sent(TOPIC, b"t", None)], 0.2)
    link.acked(report(0, 0, 0), 0.5)
    assert link.told.fates == []                           # the head alone tells nothing
    link.acked(report(1, 0b1000_0000), 1.0)
    assert link.told.fates == [(CALL, REQUEST, True)]


def command_side(sender: int) -> Reliability:
    return Reliability(sender, period=0.2, reliable={}, max_ages={CALL: 12.0},
                       max_read_length=64, commands=frozenset({CALL}))


def test_a_packet_carrying_a_command_asks_for_a_report_on_the_next_packet():
    vehicle = command_side(2)
    for number, payload in ((0, REQUEST), (1, b"\x00\x04topic")):
        vehicle.received(env.Envelope(sender=1, number=number, messages=[env.from_v1(payload)]), 0.1)
        vehicle.carrying([], 0.2, fresh=False)
        assert ("ack" in vehicle.parts(0.2)) == (payload == REQUEST)


def test_the_bridge_is_told_the_fate_as_it_offered_the_command_without_its_head():
    told: list = []
    surface, vehicle = command_side(1), command_side(2)
    surface.on_fate = lambda key, payload, arrived: told.append((key, payload, arrived))
    surface.carrying([(CALL, REQUEST)], 0.0)
    stamped = surface.stamp(CALL, REQUEST, 0.0, 0.0)               # with its age item
    surface.sent(0, [(CALL, stamped)], 0.0)
    vehicle.received(env.Envelope(sender=1, number=0, messages=[env.from_v1(stamped)]), 0.7)
    vehicle.carrying([], 0.8, fresh=False)
    ack = vehicle.parts(0.8)["ack"]
    surface.received(env.Envelope(sender=2, number=0, ack=ack), 1.5)
    assert told == [(CALL, REQUEST, True)]
    assert vehicle.stats()["reliability"]["report_bytes"] == 1 + len(ack)


def test_a_cut_command_named_with_its_tail_in_one_report_is_told_arrived():
    link = engine()
    link.sent(0, [Sent(CALL, REQUEST, None)], 0.0)
    link.cut(0)
    link.sent(1, [Sent(TOPIC, b"t", None)], 0.2)
    link.acked(report(1, 0b1000_0000), 1.0)           # both at once: the tail settles first
    assert link.told.fates == [(CALL, REQUEST, True)]


def test_a_cut_command_whose_head_is_lost_is_told_lost():
    link = engine()
    link.sent(0, [Sent(CALL, REQUEST, None)], 0.0)
    link.cut(0)
    link.sent(1, [Sent(TOPIC, b"t", None)], 0.2)
    link.acked(report(1, 0b0000_0000), 1.0)
    assert link.told.fates == [(CALL, REQUEST, False)]
