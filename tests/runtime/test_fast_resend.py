"""Loss found from acknowledgement reports (docs/wire-format.md sections 15.2-15.3): a gap is
reported on the receiver's next packet, a report that names a later packet (or, under turns,
one that rides in a turn begun after the packet) hands its reliable messages back at once
(`fast_resends`), and a lost report falls back to the retransmission timer (`timer_resends`).
Every time is explicit (the engine) or a ManualClock (the links)."""
from __future__ import annotations

import pytest

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkConfig, LinkPolicy, MacConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.acks import AckPolicy
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.delivery.reliable import ReliableLink, RttEstimator, Sent, decode_reports
from uwgen.runtime.link.mac import mac_for

SURFACE, VEHICLE = 1, 2
EPOCH = b"\x01" * 6
RELIABLE = LinkPolicy(queue="fifo", depth=20, ttl=30.0, reliable=True)
BEST_EFFORT = LinkPolicy(queue="latest", ttl=2.0)


def engine(me: int) -> ReliableLink:
    return ReliableLink(me, RttEstimator(6.0, 1.0, 60.0, 0.5), ack_delay=2.0, bitmap_bytes=1)


# -- the engine and the ack policy (explicit times) -----------------------------------------

def test_a_gap_makes_the_next_packet_carry_a_report_before_the_ack_interval():
    r = engine(VEHICLE)
    acks = AckPolicy(r, ack_delay=2.0, ack_interval=4.0)
    r.received(SURFACE, EPOCH, 0, 0.0, eliciting=False)
    assert acks.a_part({SURFACE: EPOCH}, 0.1)             # news, first report
    r.received(SURFACE, EPOCH, 1, 0.5, eliciting=False)
    assert not acks.due({SURFACE: EPOCH}, 0.6)            # no gap, within the interval: none
    r.received(SURFACE, EPOCH, 3, 1.0, eliciting=False)   # 2 is missing: it may have carried one
    assert acks.due({SURFACE: EPOCH}, 1.1)
    a_part = acks.a_part({SURFACE: EPOCH}, 1.1)
    report = decode_reports(a_part)[0]
    assert report.largest == 3 and 2 in report.numbers()[1]
    assert not acks.due({SURFACE: EPOCH}, 1.2)            # reported: nothing urgent any more
    assert not r.ack_only_due(SURFACE, 10.0)              # a gap never sends a packet alone


@pytest.mark.parametrize("twice", [True, False])
def test_a_report_telling_a_loss_rides_the_next_packet_once_more_when_said_twice(twice):
    s = engine(SURFACE)
    acks = AckPolicy(s, ack_delay=2.0, ack_interval=6.0)   # the leader's reports on the vehicle
    acks.twice = twice
    s.received(VEHICLE, EPOCH, 0, 0.0, eliciting=False)
    assert acks.a_part({VEHICLE: EPOCH}, 0.1)              # news, first report: no loss told
    assert not acks.due({VEHICLE: EPOCH}, 0.2)             # ... so not said twice
    s.received(VEHICLE, EPOCH, 2, 1.0, eliciting=False)    # 1 (say, its response) is missing
    assert 1 in decode_reports(acks.a_part({VEHICLE: EPOCH}, 1.1))[0].numbers()[1]
    assert acks.due({VEHICLE: EPOCH}, 1.3) is twice         # the turn's next packet
    again = acks.a_part({VEHICLE: EPOCH}, 1.3)
    assert bool(again) is twice
    if twice:
        assert 1 in decode_reports(again)[0].numbers()[1]
    assert not acks.due({VEHICLE: EPOCH}, 1.5) and not acks.a_part({VEHICLE: EPOCH}, 1.5)


def test_a_report_on_a_turn_taken_back_unheard_is_said_twice_by_the_leader():
    unheard = {"at": None}
    r = Reliability(SURFACE, period=0.2, reliable={}, max_ages={}, turn_gap=2.9,
                    unheard=lambda peer: unheard["at"] if peer == VEHICLE else None)
    r.acks.twice = True
    r.engine.received(VEHICLE, EPOCH, 0, 0.0, eliciting=False)
    r.acks.heard(VEHICLE, True, 0.0)
    assert r.acks.a_part({VEHICLE: EPOCH}, 0.1)
    unheard["at"] = 3.0                                    # its next turn: unheard
    assert r.acks.a_part({VEHICLE: EPOCH}, 3.1) and r.acks.a_part({VEHICLE: EPOCH}, 3.3)
    assert not r.acks.due({VEHICLE: EPOCH}, 3.5)           # twice, not more


def test_a_lost_report_that_named_a_missing_packet_goes_again_on_the_next_packet():
    s, v = engine(SURFACE), engine(VEHICLE)
    acks = AckPolicy(s, ack_delay=2.0, ack_interval=6.0)   # the surface's reports on the vehicle
    s.received(VEHICLE, EPOCH, 0, 0.0, eliciting=False)
    s.received(VEHICLE, EPOCH, 2, 0.5, eliciting=False)    # 1 (say, its response) is missing
    assert 1 in decode_reports(acks.a_part({VEHICLE: EPOCH}, 1.0))[0].numbers()[1]
    s.sent(0, acks.carried(), 1.0)                         # the packet with that report: lost
    s.sent(1, [Sent(4, "cmd", None)], 1.2)
    v.received(SURFACE, EPOCH, 1, 1.9, eliciting=False)
    assert not acks.due({VEHICLE: EPOCH}, 2.0)             # nothing new to say on its own
    s.acked(v.ack_for(SURFACE, 2.5), 3.0)                  # the vehicle's report: 0 was lost
    acks.confirm()
    assert acks.due({VEHICLE: EPOCH}, 3.1)                 # said again now, not at 7.0
    again = decode_reports(acks.a_part({VEHICLE: EPOCH}, 3.1))[0]
    assert again.largest == 2 and 1 in again.numbers()[1]


def test_a_lost_report_with_nothing_missing_waits_for_the_ack_interval():
    s, v = engine(SURFACE), engine(VEHICLE)
    acks = AckPolicy(s, ack_delay=2.0, ack_interval=6.0)
    s.received(VEHICLE, EPOCH, 0, 0.0, eliciting=False)
    s.received(VEHICLE, EPOCH, 1, 0.5, eliciting=False)
    assert acks.a_part({VEHICLE: EPOCH}, 1.0)
    s.sent(0, acks.carried(), 1.0)                         # lost; it named no packet missing
    s.sent(1, [Sent(4, "cmd", None)], 1.2)
    v.received(SURFACE, EPOCH, 1, 1.9, eliciting=False)
    s.acked(v.ack_for(SURFACE, 2.5), 3.0)
    acks.confirm()
    assert not acks.due({VEHICLE: EPOCH}, 3.1)


def test_a_report_naming_a_later_packet_hands_the_message_back_at_once():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(8, "mission", deadline=30.0)], 0.0)
    s.sent(1, [Sent(4, "cmd", None)], 0.2)
    r.received(SURFACE, EPOCH, 1, 0.9, eliciting=False)
    s.acked(r.ack_for(SURFACE, 1.0), 1.7)
    assert [m.ref for m in s.due(1.7)] == ["mission"]      # not after RTO + ack delay (8 s)
    assert (s.fast_resends, s.timer_resends) == (1, 0)


def test_under_turns_a_report_below_a_packet_sent_before_the_turn_settles_it_as_lost():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(4, "cmd", None)], 0.0)
    s.sent(1, [Sent(8, "mission", deadline=30.0)], 0.2)    # the turn's last packet: lost
    r.received(SURFACE, EPOCH, 0, 0.7, eliciting=False)
    report = r.ack_for(SURFACE, 1.0)
    s.acked(report, 1.7)                                   # no MAC: nothing says 1 is lost
    assert s.due(1.7) == []
    s.acked(report, 1.8, settled_by=0.2)                   # the turn began after packet 1
    assert [m.ref for m in s.due(1.8)] == ["mission"] and s.fast_resends == 1
    # the packet stays in flight for the ledger, and is not handed back twice
    assert s.in_flight() == {8: 1}
    s.acked(report, 1.9, settled_by=0.2)
    assert s.due(1.9) == [] and s.fast_resends == 1


def test_a_report_that_held_its_largest_longer_than_it_can_say_gives_no_round_trip_sample():
    s, r = engine(SURFACE), engine(VEHICLE)
    s.sent(0, [Sent(4, "cmd", None)], 0.0)
    r.received(SURFACE, EPOCH, 0, 0.7, eliciting=False)
    s.acked(r.ack_for(SURFACE, 6.0), 6.7)                  # held 5.3 s: R1 says 3.75 at most
    assert s.rtt.samples == 0 and s.rtt.srtt is None
    s.sent(1, [Sent(4, "cmd", None)], 7.0)
    r.received(SURFACE, EPOCH, 1, 7.7, eliciting=False)
    s.acked(r.ack_for(SURFACE, 8.0), 8.7)                  # held 0.3 s: a sample of 1.5 s
    assert s.rtt.samples == 1 and abs(s.rtt.srtt - 1.5) < 0.3


def test_a_lost_report_falls_back_to_the_timer():
    s = engine(SURFACE)
    s.sent(0, [Sent(8, "mission", deadline=30.0)], 0.0)
    s.sent(1, [Sent(4, "cmd", None)], 0.2)
    # the peer's report naming packet 1 (and 0 missing) is lost: nothing arrives
    assert s.due(7.9) == [] and s.next_timeout() == 8.0    # RTO 6 s + ack delay 2 s
    assert [m.ref for m in s.due(8.0)] == ["mission"]
    assert (s.fast_resends, s.timer_resends) == (0, 1)


# -- two links under turns (a ManualClock) ------------------------------------------------

TURNS = MacConfig(mode="turns", range=1000.0, leader="surface",
                  packets=(("surface", 4), ("vehicle", 2)), bitrate=4800.0)
SENDERS = {"surface": SURFACE, "vehicle": VEHICLE}
MISSION, CMD, POSE = 8, 4, 5


class Wall:
    def __init__(self, clock: ManualClock):
        self.clock = clock

    def now(self) -> float:
        return 1.7e9 + self.clock.now()


def turns_pair(mac: MacConfig = TURNS, cmd_every: float = 0.5):
    scen = Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(1000, 0, 0), dest="surface")],
                    period=0.2, max_read_length=64, bitrate=4800.0)
    clock = ManualClock()
    macs = {side: mac_for(mac, side, SENDERS, LinkConfig(64, 0.2)) for side in SENDERS}
    rel = {}

    def hooks_for(side):
        rel[side] = Reliability(SENDERS[side], period=0.2, reliable={MISSION: 30.0},
                                max_ages={MISSION: 30.0}, wall=Wall(clock), name=side,
                                max_read_length=64, other_overhead=macs[side].overhead,
                                turn_gap=macs[side].turn_gap(), settled_by=macs[side].settled_by,
                                unheard=macs[side].unheard)
        return rel[side].hooks()
    sim = DuplexSim(scen, ("surface", "vehicle"), hooks_for=hooks_for, wire_format=2, clock=clock,
                    step=0.025, link_kw_for=lambda side: {"mac": macs[side], "sender_id": SENDERS[side]})
    written: dict[str, list] = {s: [] for s in SENDERS}
    for side, link in sim.links.items():
        sent = link.hooks.sent

        def spy(number, picked, now, side=side, sent=sent):
            keys = [("m", rel[side].heads.take(p).payload[2]) if k == MISSION else k
                    for k, p in picked]
            written[side].append((now, number, keys))
            return sent(number, picked, now)
        link.hooks.sent = spy
    sim.links["surface"].add_channel(MISSION, RELIABLE)
    sim.links["surface"].add_channel(CMD, BEST_EFFORT)
    sim.links["vehicle"].add_channel(POSE, BEST_EFFORT)
    for k in range(int(60 / cmd_every)):                   # both sides talk, as the demo's
        sim.at(0.1 + cmd_every * k,
               lambda k=k: sim.links["surface"].offer(CMD, bytes((0, CMD, k % 256)) + bytes(8)))
    for k in range(120):
        sim.at(0.3 + 0.5 * k, lambda k=k: sim.links["vehicle"].offer(POSE, bytes((0, POSE, k)) + bytes(8)))
    return sim, rel, written


def mission_copies(written, k: int) -> list[tuple[float, int]]:
    """(time, packet number) of each surface packet that carried mission message k."""
    return [(t, n) for t, n, keys in written["surface"] if ("m", k) in keys]


def offer_missions(sim, count: int, every: float = 2.0, start: float = 3.0):
    for k in range(count):
        sim.at(start + every * k,
               lambda k=k: sim.links["surface"].offer(MISSION, bytes((0, MISSION, k)) + bytes(10)))


def test_under_turns_a_lost_message_goes_again_in_the_senders_next_turn_not_after_its_timer():
    sim, rel, written = turns_pair()
    offer_missions(sim, 1)
    sim.run(2.9)
    sim.drop("surface", len(written["surface"]))           # the next write: it carries the message
    sim.run(25.0)
    copies = mission_copies(written, 0)
    assert len(copies) == 2
    assert [p[2] for _, p in sim.received["vehicle"] if p[1] == MISSION] == [0]
    engine = rel["surface"].engine
    assert (engine.fast_resends, engine.timer_resends) == (1, 0)
    # the copy left in the surface's first turn after the vehicle's answer: within one round
    # of turns, well before the timer (RTO + ack delay) could have fired
    cycle = sim.links["surface"].mac.cycle()
    assert copies[1][0] - copies[0][0] < cycle < engine.rtt.rto + engine.ack_delay


def test_a_lost_grant_is_carried_by_its_notice_and_a_message_in_it_goes_again_next_turn():
    # a busy surface with 2-packet turns: every turn runs full, notice then grant
    busy = MacConfig(mode="turns", range=1000.0, leader="surface",
                     packets=(("surface", 2), ("vehicle", 2)), bitrate=4800.0)
    sim, rel, written = turns_pair(busy, cmd_every=0.1)
    surface = sim.links["surface"].mac
    state = {"offered": False, "lost": None}
    sent = sim.links["surface"].hooks.sent

    def after_a_notice_lose_the_grant_and_its_message(number, picked, now):
        closing = surface._closing
        notice = closing is None and surface._sent == surface._granted - 1   # this packet's
        if now > 5.0 and not state["offered"] and notice:
            state["offered"] = True               # the next packet grants: it will carry this
            sim.at(now + 0.01, lambda: sim.links["surface"].offer(
                MISSION, bytes((0, MISSION, 0)) + bytes(10)))
        if state["lost"] is None and closing is not None and closing.count and \
                any(k == MISSION for k, _ in picked):
            state["lost"] = number
            sim.drop("surface", sim.written["surface"])
        return sent(number, picked, now)
    sim.links["surface"].hooks.sent = after_a_notice_lose_the_grant_and_its_message
    sim.run(30.0)
    assert state["lost"] is not None, "the grant packet did not carry the message"
    vehicle = sim.links["vehicle"].mac
    assert vehicle.counts["turns_from_notice"] == 1 and surface.counts["missed"] == 0
    copies = mission_copies(written, 0)
    assert copies[0][1] == state["lost"] and len(copies) == 2
    # the vehicle's answer (in the turn the notice gave it) settles the grant's packet as
    # lost: the copy goes in the surface's very next turn, no timer
    assert copies[1][0] - copies[0][0] < surface.cycle()
    engine = rel["surface"].engine
    assert (engine.fast_resends, engine.timer_resends) == (1, 0)
    assert [p[2] for _, p in sim.received["vehicle"] if p[1] == MISSION] == [0]
    for side in SENDERS:
        assert sim.core.counters(side)["lost_collision"] == 0


def test_under_a_mac_news_of_best_effort_packets_is_reported_every_two_rounds_a_gap_at_once():
    def policy(turn_gap: float) -> Reliability:
        r = Reliability(VEHICLE, period=0.2, reliable={}, max_ages={}, turn_gap=turn_gap)
        r.engine.received(SURFACE, EPOCH, 0, 0.0, eliciting=False)
        r.acks.heard(SURFACE, True, 0.0)
        assert r.acks.a_part({SURFACE: EPOCH}, 0.1)               # the first report
        r.engine.received(SURFACE, EPOCH, 1, 1.0, eliciting=False)
        r.acks.heard(SURFACE, True, 1.0)
        return r
    assert policy(0.0).acks.due({SURFACE: EPOCH}, 3.0)            # no MAC: every 2 s
    r = policy(2.9)                                               # a round of turns of 2.9 s
    assert not r.acks.due({SURFACE: EPOCH}, 3.0)
    assert r.acks.due({SURFACE: EPOCH}, 0.1 + 2 * 2.9)
    r.engine.received(SURFACE, EPOCH, 3, 3.5, eliciting=False)    # 2 is missing
    assert r.acks.due({SURFACE: EPOCH}, 3.5)


def test_under_turns_a_followers_turn_lost_whole_is_reported_at_once_and_its_message_goes_next_turn():
    # The vehicle's turn carrying a reliable message is lost, its end with it: the surface,
    # with no news, reports all the same on its next packet (the MAC took the turn back
    # unheard), and that report settles the vehicle's turn as lost.
    sim, rel, written = turns_pair()
    sim.links["vehicle"].add_channel(MISSION, RELIABLE)
    vehicle_sent = sim.links["vehicle"].hooks.sent
    lost: dict[str, float] = {}

    def lose_the_turn_carrying_it(number, picked, now):
        if "at" not in lost and any(k == MISSION for k, _ in picked):
            lost["at"] = now
        if "at" in lost and now - lost["at"] < 0.6:        # the rest of that turn too
            sim.drop("vehicle", sim.written["vehicle"])
        return vehicle_sent(number, picked, now)
    sim.links["vehicle"].hooks.sent = lose_the_turn_carrying_it
    sim.at(10.0, lambda: sim.links["vehicle"].offer(MISSION, bytes((0, MISSION, 7)) + bytes(10)))
    sim.run(40.0)
    assert "at" in lost
    surface = sim.links["surface"].mac
    assert surface.counts["missed"] >= 1
    engine = rel["vehicle"].engine
    assert (engine.fast_resends, engine.timer_resends) == (1, 0)
    copies = [t for t, _n, keys in written["vehicle"] if ("m", 7) in keys]
    assert len(copies) == 2 and copies[1] - copies[0] < surface.cycle() + 0.5
    assert [p[2] for _, p in sim.received["surface"] if p[1] == MISSION] == [7]


def test_a_report_on_a_peer_whose_turn_went_unheard_is_due_once_news_or_not():
    unheard = {"at": None}
    r = Reliability(SURFACE, period=0.2, reliable={}, max_ages={}, turn_gap=2.9,
                    unheard=lambda peer: unheard["at"] if peer == VEHICLE else None)
    r.engine.received(VEHICLE, EPOCH, 0, 0.0, eliciting=False)
    r.acks.heard(VEHICLE, True, 0.0)
    assert r.acks.a_part({VEHICLE: EPOCH}, 0.1)                   # the first report
    assert not r.acks.due({VEHICLE: EPOCH}, 3.0)                  # nothing new: none due
    unheard["at"] = 3.0                                           # its next turn: unheard
    assert r.acks.due({VEHICLE: EPOCH}, 3.1)
    assert r.acks.a_part({VEHICLE: EPOCH}, 3.1)
    assert not r.acks.due({VEHICLE: EPOCH}, 3.2)                  # once per unheard turn
