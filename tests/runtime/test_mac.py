"""The link's MAC (uwgen.runtime.link.mac): turns, TDMA's share of a slot, and C items,
with explicit times (sans-IO)."""
from __future__ import annotations

import math

import pytest

from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac import (TURN_END, TURN_GRANT, Mac, MacItem, TdmaMac, TurnMac,
                                    decode_items, encode_items, mac_for, tdma_capacity)
from uwgen.runtime.link.turn_timing import LISTEN, REACT
from uwgen.security import control

LINK = LinkConfig(max_read_length=64, period=0.2)
TURNS = MacConfig(mode="turns", range=300, leader="surface", packets=(("surface", 3), ("vehicle", 2)))
SENDERS = {"surface": 1, "vehicle": 2}


def pair(leader_packets: int = 3):
    """(leader, follower); a one-packet leader turn is its grant alone (no notice before it)."""
    turns = MacConfig(mode="turns", range=300, leader="surface",
                      packets=(("surface", leader_packets), ("vehicle", 2)))
    return (TurnMac(turns, "surface", SENDERS, LINK), TurnMac(turns, "vehicle", SENDERS, LINK))


def write(mac: TurnMac, now: float) -> bytes:
    """One packet built and written at `now` (what the packer and the connection do)."""
    assert mac.next_write_at(now) <= now
    c = mac.parts(now)
    mac.wrote(now, 20)
    return c


def test_turn_items_have_the_documented_bytes():
    # docs/wire-format.md section 16: a grant to sender 2 for 3 packets, sender 2's end.
    assert encode_items([MacItem(TURN_GRANT, 2, 3)]).hex(" ") == "22 03"
    assert encode_items([MacItem(TURN_END, 2)]).hex(" ") == "32"
    # A C part with the seal's sync request for sender 1 first, then the grant.
    c = control.sync_request(1) + encode_items([MacItem(TURN_GRANT, 2, 3)])
    assert c.hex(" ") == "11 22 03"
    assert decode_items(c) == [MacItem(TURN_GRANT, 2, 3)]
    assert [(i.code, i.sender) for i in control.items(c)] == [(1, 1), (2, 2)]


def test_a_cut_grant_and_unknown_codes_are_skipped():
    assert decode_items(bytes([0x22])) == []
    assert decode_items(bytes([0x5F, 0x32])) == [MacItem(TURN_END, 2)]


def test_mode_none_always_allows():
    mac = mac_for(MacConfig(), "surface", SENDERS, LINK)
    assert type(mac) is Mac and mac.next_write_at(0.0) == -math.inf and mac.hooks() is None


def test_the_leader_grants_after_its_packets_and_waits_for_the_end():
    lead, follower = pair(leader_packets=4)
    lead.carries = True                              # its packets carry messages
    lead.backlog = lambda now: True                  # and more waits after each
    assert write(lead, 0.0) == b""
    assert write(lead, 0.21) == bytes([0x22, 0])     # the second and third: notices of the grant
    assert write(lead, 0.42) == bytes([0x22, 0])
    grant = write(lead, 0.63)                        # the fourth packet carries the grant
    assert grant == bytes([0x22, 2])
    assert lead.next_write_at(0.7) > 0.7              # waiting for the vehicle's turn
    assert follower.next_write_at(0.7) == math.inf    # nothing heard yet: silent
    follower.heard(1, grant, 0.7)
    follower.backlog = lambda now: False
    assert follower.must_send(0.7)                    # even with nothing to say: the end
    end = write(follower, 0.7)
    assert end == bytes([0x32])
    assert follower.next_write_at(0.8) == math.inf
    lead.heard(2, end, 1.1)
    assert lead.next_write_at(1.1) == -math.inf
    assert lead.counts["ends_heard"] == 1 and lead.counts["missed"] == 0
    assert lead.rtt[2].samples == 1 and lead.rtt[2].srtt == pytest.approx(1.1 - 0.63)


def test_the_leader_gives_two_notices_from_its_first_packet_without_messages_then_grants():
    lead, _ = pair(leader_packets=5)
    lead.carries = True
    lead.backlog = lambda now: True
    assert write(lead, 0.0) == b""
    lead.carries = False                             # nothing more: two notices, then the grant
    assert write(lead, 0.21) == bytes([0x22, 0])
    lead.carries = True                              # what comes meanwhile rides in their packets
    assert write(lead, 0.42) == bytes([0x22, 0])
    assert write(lead, 0.63) == bytes([0x22, 2])
    assert lead.next_write_at(0.7) > 0.7             # the turn is the follower's


def test_an_idle_leader_still_gives_two_notices_before_its_grant():
    lead, _ = pair()
    lead.carries = False
    notice = bytes([0x22, 0])
    assert [write(lead, t) for t in (0.0, 0.21, 0.42)] == [notice, notice, bytes([0x22, 2])]


def test_a_leader_whose_queue_ran_empty_long_after_its_last_offer_gives_notice_on_that_packet():
    """Sparse commands: the packet that takes the last waiting message carries the first
    notice, so the turn spends no packet on waiting; a message offered within the last
    interval (a stream at the link's pace) keeps the turn going instead."""
    notice = bytes([0x22, 0])
    lead, _ = pair(leader_packets=5)
    lead.carries, lead.backlog = True, (lambda now: False)
    lead.offered_at = 1.0 - 2 * lead.interval
    assert [write(lead, t) for t in (1.0, 1.21, 1.42)] == [notice, notice, bytes([0x22, 2])]
    stream, _ = pair(leader_packets=6)
    stream.carries, stream.backlog = True, (lambda now: False)
    for t in (1.0, 1.21, 1.42):
        stream.offered_at = t - 0.1
        assert write(stream, t) == b""


def test_a_one_packet_leader_turn_is_its_grant_alone():
    lead, _ = pair(leader_packets=1)
    lead.carries = True
    assert write(lead, 0.0) == bytes([0x22, 2])


def test_a_follower_writes_at_most_the_packets_granted():
    _, follower = pair()
    follower.backlog = lambda now: True
    follower.heard(1, bytes([0x22, 2]), 0.0)
    assert write(follower, 0.0) == b""
    assert write(follower, 0.21) == bytes([0x32])
    assert follower.next_write_at(0.3) == math.inf


def test_a_lost_grant_or_end_is_counted_and_the_leader_takes_the_turn_back():
    lead, _ = pair(leader_packets=1)
    lead.backlog = lambda now: False
    write(lead, 0.0)                                 # grant-only packet
    deadline = lead.next_write_at(0.1)
    assert 0.1 < deadline < 10
    assert lead.next_write_at(deadline) == -math.inf  # recovered within the round
    assert lead.counts["missed"] == 1
    assert write(lead, deadline) == bytes([0x22, 2])  # and grants again


def test_a_follower_that_starts_late_answers_the_next_grant_naming_it():
    lead, _ = pair()
    late = TurnMac(TURNS, "vehicle", SENDERS, LINK)
    late.heard(1, bytes([0x22, 2]), 5.0)
    assert late.next_write_at(5.0) == -math.inf and late.counts["grants_heard"] == 1


def test_a_follower_ignores_grants_from_others_and_for_others():
    three = MacConfig(mode="turns", leader="surface")
    senders = {"surface": 1, "auv1": 2, "auv2": 3}
    auv1 = TurnMac(three, "auv1", senders, LINK)
    auv1.heard(3, bytes([0x22, 4]), 0.0)             # not the leader
    assert auv1.next_write_at(0.0) == math.inf
    auv1.heard(1, bytes([0x23, 4]), 0.0)             # the leader, for auv2
    assert auv1.next_write_at(0.0) == math.inf and auv1.counts["not_mine"] == 1


def test_the_leader_grants_each_follower_in_turn():
    three = MacConfig(mode="turns", leader="surface", packets=(("surface", 1),))
    senders = {"surface": 1, "auv1": 2, "auv2": 3}
    lead = TurnMac(three, "surface", senders, LINK)
    grants = []
    t = 0.0
    for _ in range(3):
        c = write(lead, t)
        grants.append(c[0] & 0x0F)
        lead.heard(c[0] & 0x0F, bytes([0x30 | (c[0] & 0x0F)]), t + 1.0)
        t += 1.0
    assert grants == [2, 3, 2]


def test_a_follower_drops_a_turn_it_could_not_use_in_time():
    _, follower = pair()
    follower.heard(1, bytes([0x22, 2]), 0.0)
    assert follower.next_write_at(10.0) == math.inf and follower.counts["dropped_turns"] == 1


def test_turn_gap_and_overhead_are_what_delivery_and_the_packer_need():
    lead, follower = pair()
    assert lead.overhead == 3
    assert follower.turn_gap() == pytest.approx(lead.turn_gap())
    assert lead.turn_gap() > 5 * 0.2


def test_tdma_writes_at_most_a_slots_capacity_per_frame():
    # frame 1 s, 2 slots, guard 0.35: ON 0.15 s; a 64-byte packet takes 0.113 s, and DESERT
    # starts packets anywhere in ON: 2 a frame.
    config = MacConfig(mode="tdma", frame=1.0, guard=0.35, slots=("surface", "vehicle"),
                       max_packet_per_slot=1000, range=300)
    assert tdma_capacity(config, LINK) == 2
    mac = TdmaMac(config, "surface", LINK, senders={"surface": 1, "vehicle": 2})
    mac.arrived(64, 10.0 + 0.5 + 68 * 8 / 4800 + 0.2)  # the vehicle's slot of frames at 10 + k
    mac.heard(2, b"", 10.0 + 0.5 + 68 * 8 / 4800 + 0.2)
    t = mac.next_write_at(10.9)
    for _ in range(2):
        assert mac.next_write_at(t) == -math.inf
        mac.wrote(t, 64)
        t += 0.21
    assert mac.next_write_at(t) == pytest.approx(t - 0.42 + 1.0)   # the next frame's window
    assert mac.turn_gap() == 1.0


@pytest.mark.parametrize("kw, capacity", [
    ({"max_packet_per_slot": 1}, 1),              # DESERT's default
    ({"guard": 0.05, "max_packet_per_slot": 1000}, 4),   # ON 0.45 s: 4 starts of 0.113 s
    ({"guard": 0.05, "max_packet_per_slot": 1000, "queue_size": 3}, 3),
    # the guard is shorter than a packet and the range's delay (0.2 s): a packet must start
    # by 0.5 - 0.113 - 0.2 s to end before the next slot: 2, not 4
    ({"guard": 0.05, "max_packet_per_slot": 1000, "range": 300}, 2),
    ({"guard": 0.05, "range": 2000}, 1),                # not even one fits: the first goes
])
def test_tdma_capacity_follows_desert_settings(kw, capacity):
    config = MacConfig(mode="tdma", frame=1.0, slots=("a", "b"), **{"range": 30, **kw})
    assert tdma_capacity(config, LINK) == capacity


def test_an_end_lost_after_the_answer_costs_an_interval_and_a_tick_after_the_heard_packet():
    lead, _ = pair(leader_packets=1)
    write(lead, 0.0)                                 # grants sender 2 two packets
    assert lead.next_write_at(0.1) > 1.0             # the first bound is longer
    lead.arrived(64, 0.8)                            # its first packet, full size, ended arriving at 0.8
    lead.heard(2, b"", 0.8)                          # ... and the one with the end is lost
    start = 0.8 - (64 + 4) * 8 / 4800                # it started arriving one air time before
    # the end was written at most an interval (and a late wake-up) after it, then waited at
    # most DESERT's tick and its listen: by then it has started arriving or it never will
    bound = start + lead.interval + REACT + LINK.period + LISTEN
    assert lead.next_write_at(0.9) == pytest.approx(bound) and bound < 0.8 + 3 * lead.interval
    assert lead.next_write_at(bound) == -math.inf and lead.counts["missed"] == 1


def test_the_first_turn_timer_is_the_manifests_worst_case_and_one_slow_turn_does_not_inflate_it():
    lead, _ = pair(leader_packets=1)
    lead.carries = False
    one_way = LINK.period + LISTEN + (64 + 4) * 8 / 4800 + 300 / 1500   # written -> arrived, 300 m
    # the grant arrives, the follower writes within REACT and one interval later its second
    # packet, which starts arriving a tick, a listen and the range's delay after
    worst = one_way + REACT + lead.interval + LINK.period + LISTEN + 300 / 1500
    write(lead, 0.0)
    assert lead.next_write_at(0.1) == pytest.approx(worst)
    lead.heard(2, bytes([0x32]), 1.0)                # a slow turn: its end heard at 1.0 s
    write(lead, 1.0)
    assert lead.next_write_at(1.1) == pytest.approx(1.0 + worst)     # the same bound, not 3 x 1.0 s


@pytest.mark.parametrize("heard_notice", [0, 1])
def test_a_follower_that_answers_from_a_notice_is_never_talked_over(heard_notice):
    """Whichever notice it heard alone (the first or the last before the grant), the follower
    starts after the grant's packet has ended and writes inside the leader's bound."""
    lead, follower = pair(leader_packets=4)
    t = 0.0
    for _ in range(8):                               # quick turns: measured round trips short
        lead.carries = False
        for k in range(3):
            write(lead, t + k * 0.21)                # two notices, the grant
        lead.heard(2, bytes([0x32]), t + 0.8)
        t += 0.8
    lead.carries = True
    lead.backlog = lambda now: True
    write(lead, t)
    notices = [write(lead, t + 0.21), write(lead, t + 0.42)]
    grant = write(lead, t + 0.63)                    # lost on its way, as the other notice
    assert notices == [bytes([0x22, 0])] * 2 and grant == bytes([0x22, 2])
    timing = follower.timing
    heard = t + 0.21 * (1 + heard_notice) + timing.one_way   # heard as late as it can be
    follower.heard(1, notices[heard_notice], heard)
    follower.backlog = lambda now: True
    start = follower.next_write_at(heard)
    assert start >= t + 0.63 + timing.one_way        # the grant's packet has ended everywhere
    write(follower, start)
    last = start + REACT                             # its second packet, written as late as allowed
    assert follower.next_write_at(last) == -math.inf and write(follower, last) == bytes([0x32])
    assert lead.next_write_at(t + 0.7) >= timing.arriving_by(last)


def test_a_leader_whose_grant_is_late_after_its_notice_does_not_write_it_over_the_follower():
    """The leader's thread stalls after its notice: the follower that heard the notice starts
    its turn from it before a grant written that late could end. The leader writes no
    grant, counts it, and waits for the follower's turn as if the notice had granted it."""
    lead, follower = pair()
    lead.carries = False
    notice = write(lead, 0.0)
    assert notice == bytes([0x22, 0])
    heard = lead.timing.one_way                      # the notice heard as late as it can be
    follower.heard(1, notice, heard)
    start = follower.next_write_at(heard)            # the follower's turn, from the notice
    late = lead.interval + REACT + 0.5               # the stalled leader wakes up
    assert late < start
    assert lead.next_write_at(late) > late and not lead.must_send(late)   # no grant now
    assert (lead.counts["late_grants"], lead.counts["grants_sent"]) == (1, 0)
    follower.backlog = lambda now: False
    end = write(follower, start)
    assert end == bytes([0x32])
    assert lead.next_write_at(start) >= lead.timing.arriving_by(start)   # its answer is awaited
    lead.heard(2, end, start + 0.3)
    assert lead.next_write_at(start + 0.3) == -math.inf and lead.counts["missed"] == 0


def test_a_leader_grants_on_time_after_its_notices_with_a_thread_a_little_late():
    lead, _ = pair()
    lead.carries = False
    write(lead, 0.0)
    assert write(lead, lead.interval + REACT - 0.01) == bytes([0x22, 0])
    # no later than two intervals and REACT after the first notice, whatever the second did
    assert write(lead, 2 * lead.interval + REACT - 0.01) == bytes([0x22, 2])
    assert lead.counts["late_grants"] == 0


def test_a_grant_ready_only_after_the_followers_turn_from_its_notice_began_is_not_written():
    """The leader's thread stalls between building its grant and writing it (the connection
    asks `late` with its clock read again): written then, the grant would meet the turn the
    follower took from the notice. It is dropped (`abandoned`), and the leader waits for
    that turn as if the notice had granted it."""
    lead, _ = pair()
    lead.carries = False
    write(lead, 0.0)                                    # the notices
    write(lead, lead.interval)
    on_time = 2 * lead.interval
    assert lead.next_write_at(on_time) <= on_time
    assert lead.parts(on_time) == bytes([0x22, 2])      # the grant, built on time
    assert not lead.late(on_time + 0.05)
    stalled = 2 * lead.interval + REACT + 0.5
    assert lead.late(stalled)
    lead.abandoned()
    assert (lead.counts["late_grants"], lead.counts["grants_sent"]) == (1, 0)
    assert lead.next_write_at(stalled) > stalled       # the follower's turn is awaited
    lead.heard(2, bytes([0x32]), stalled + 0.5)
    assert lead.next_write_at(stalled + 0.5) == -math.inf and lead.counts["missed"] == 0


def test_a_follower_packet_ready_after_its_window_is_not_written_and_a_timely_one_is():
    _, follower = pair()
    follower.backlog = lambda now: False
    follower.heard(1, bytes([0x22, 2]), 0.0)
    assert follower.parts(0.0) == bytes([0x32])         # its end, built at once
    assert not follower.late(0.05)
    assert follower.late(follower.timing.window(0.0, 2) + 0.01)
    follower.abandoned()
    assert follower.counts["dropped_turns"] == 1 and follower.counts["turns"] == 0
    assert not Mac().late(5.0)                           # mode none: DESERT's MAC decides


def test_a_late_follower_writes_only_inside_its_window_and_ends_its_turn_there():
    _, follower = pair()
    follower.backlog = lambda now: True
    follower.heard(1, bytes([0x22, 2]), 0.0)
    # its thread woke late: no room for a second packet in the window the leader counts on
    assert write(follower, 0.2) == bytes([0x32])
    _, slow = pair()
    slow.heard(1, bytes([0x22, 2]), 0.0)
    assert slow.next_write_at(0.4) == math.inf and slow.counts["dropped_turns"] == 1


def test_an_answer_later_than_the_bound_lengthens_the_next_bounds():
    lead, _ = pair(leader_packets=1)
    lead.carries = False
    write(lead, 0.0)
    first = lead.next_write_at(0.1)
    lead.next_write_at(first)                        # nothing heard: taken back, missed
    lead.heard(2, b"", first + 0.3)                  # its answer came after all: the range is longer
    assert lead.counts["late_answers"] == 1
    write(lead, first)
    assert lead.next_write_at(first + 0.1) > first + first + 0.3 - REACT


def test_the_leader_gives_notice_of_its_grant_on_the_two_packets_before_it():
    lead, _ = pair(leader_packets=4)
    lead.carries = True
    lead.backlog = lambda now: True                  # a full turn: the count ends it
    items = [write(lead, t) for t in (0.0, 0.21, 0.42, 0.63)]
    assert items == [b"", bytes([0x22, 0]), bytes([0x22, 0]), bytes([0x22, 2])]
    assert decode_items(items[1]) == [MacItem(TURN_GRANT, 2, 0)]
    assert [(i.code, i.sender) for i in control.items(items[2] + items[3])] == [(2, 2), (2, 2)]
    short, _ = pair(leader_packets=2)                # room for one notice only
    short.carries, short.backlog = True, (lambda now: True)
    assert [write(short, t) for t in (0.0, 0.21)] == [bytes([0x22, 0]), bytes([0x22, 2])]


@pytest.mark.parametrize("second", [1.05, 1.25])
def test_a_follower_that_heard_both_notices_but_lost_the_grant_starts_when_either_allows(second):
    """The grant leaves no later than two intervals after the first notice and one after the
    second (and REACT): the follower starts by the earlier of the two bounds."""
    _, follower = pair()
    follower.heard(1, bytes([0x22, 0]), 1.0)
    follower.heard(1, bytes([0x22, 0]), second)      # the last before the grant
    after = 0.2 + follower.air + 0.05                # a tick, the grant's air, a listen
    start = min(1.0 + 2 * follower.interval, second + follower.interval) + after
    assert follower.next_write_at(second) == pytest.approx(start)


def test_a_follower_that_heard_one_notice_but_lost_the_grant_takes_its_turn_two_intervals_after_it():
    _, follower = pair()
    follower.backlog = lambda now: True
    follower.heard(1, bytes([0x22, 0]), 1.0)         # the first or the last: taken for the first
    start = 1.0 + 2 * follower.interval + 0.2 + follower.air + 0.05   # the grant's packet has ended
    assert follower.next_write_at(1.1) == pytest.approx(start)
    assert follower.next_write_at(start) == -math.inf and follower.counts["turns_from_notice"] == 1
    assert write(follower, start) == b""
    assert write(follower, start + 0.21) == bytes([0x32])      # the manifest's 2 packets, then the end
    assert follower.next_write_at(start + 0.3) == math.inf


def test_a_grant_heard_after_its_notices_turn_was_taken_starts_no_second_turn():
    # the leader's DESERT sent the grant late: the follower had taken its turn from the
    # notice and ended it, and the leader took the turn back on that end; a second turn
    # from the late grant collided with the leader's next packet
    _, follower = pair()
    follower.backlog = lambda now: False
    follower.heard(1, bytes([0x22, 0]), 1.0)
    start = follower.next_write_at(1.1)
    assert follower.next_write_at(start) == -math.inf
    assert write(follower, start) == bytes([0x32])              # nothing to send: the end
    follower.heard(1, bytes([0x22, 2]), start + 0.05)           # the late grant
    assert follower.next_write_at(start + 0.1) == math.inf and follower.counts["late_grants"] == 1
    follower.heard(1, b"", start + 1.0)                          # the leader's turn
    follower.heard(1, bytes([0x22, 2]), start + 1.2)             # the next round's grant
    assert follower.next_write_at(start + 1.2) == -math.inf and follower.counts["grants_heard"] == 1


def test_a_grant_after_its_notice_starts_the_turn_at_once_and_others_notices_are_ignored():
    _, follower = pair()
    follower.heard(1, bytes([0x22, 0]), 1.0)
    follower.heard(1, bytes([0x22, 2]), 1.21)
    assert follower.next_write_at(1.21) == -math.inf and follower.counts["turns_from_notice"] == 0
    _, other = pair()
    other.heard(1, bytes([0x23, 0]), 1.0)                       # notice for sender 3
    other.heard(3, bytes([0x22, 0]), 1.0)                       # not from the leader
    assert other.next_write_at(5.0) == math.inf


def test_settled_by_says_until_when_a_peers_answer_covers_this_sides_packets():
    lead, follower = pair(leader_packets=1)
    assert Mac().settled_by(2, 1.0) is None
    lead.carries = False
    write(lead, 0.42)                                           # the grant
    assert lead.settled_by(2, 1.1) == 0.42 and lead.settled_by(3, 1.1) is None
    follower.backlog = lambda now: False
    follower.heard(1, bytes([0x22, 2]), 0.9)
    assert follower.settled_by(1, 0.9) is None                  # its turn: nothing settled yet
    write(follower, 0.9)                                        # the end
    assert follower.settled_by(1, 2.0) == 0.9 and follower.settled_by(3, 2.0) is None


def test_settled_by_covers_a_turns_last_packet_built_after_the_connection_read_its_clock():
    # the connection reads its clock, then builds the packet (delivery keeps it by its build
    # time, a little later), then writes it and tells the MAC with its first reading: the
    # packet carrying the grant or the end is one of the turn's, whatever lies between
    lead, follower = pair(leader_packets=1)
    lead.carries = False
    assert lead.next_write_at(0.42) <= 0.42
    lead.parts(0.4231)                                          # the grant, built
    lead.wrote(0.42, 20)
    assert lead.settled_by(2, 1.1) == 0.4231
    follower.backlog = lambda now: False
    follower.heard(1, bytes([0x22, 2]), 0.9)
    follower.parts(0.9047)                                      # the end, built
    follower.wrote(0.9, 20)
    assert follower.settled_by(1, 2.0) == 0.9047


def test_unheard_says_when_the_leader_last_took_a_followers_turn_back_on_its_timer():
    lead, follower = pair(leader_packets=1)
    assert Mac().unheard(2) is None
    lead.carries = False
    write(lead, 0.42)                                           # the grant, never answered
    assert lead.unheard(2) is None
    deadline = lead.next_write_at(0.5)
    assert math.isfinite(deadline) and lead.next_write_at(deadline) == -math.inf
    assert lead.counts["missed"] == 1 and lead.unheard(2) == deadline
    assert lead.unheard(3) is None and follower.unheard(1) is None


def test_only_the_turns_leader_says_a_loss_report_twice():
    # its notices and grant follow its first packet within the turn; a follower's turn is
    # often one packet, and TDMA and no MAC have no turn (delivery's AckPolicy.twice)
    lead, follower = pair()
    assert lead.reports_twice() and not follower.reports_twice()
    assert not Mac().reports_twice()
    tdma = MacConfig(mode="tdma", frame=3.0, guard=0.2, slots=("surface", "vehicle"),
                     max_packet_per_slot=1000, queue_size=100, range=100)
    assert not TdmaMac(tdma, "surface", LINK).reports_twice()


def test_a_weighted_tdma_slot_drains_more_packets_a_frame():
    # frame 3 s over 3 sides, the surface weighted 4 of 6: its slot is 2 s (ON 1.8 s), the
    # others 0.5 s (ON 0.3 s); 64-byte packets take 0.113 s, one per 0.2 s period
    config = MacConfig(mode="tdma", frame=3.0, guard=0.2, slots=("surface", "auv1", "auv2"),
                       max_packet_per_slot=1000, queue_size=100, weights=(("surface", 4),),
                       range=100)
    assert tdma_capacity(config, LINK, "surface") == 15      # by the period: 3 s / 0.2 s
    assert tdma_capacity(config, LINK, "auv1") == 3          # floor(0.3 / 0.113) + 1
    assert TdmaMac(config, "surface", LINK).capacity == 15
    assert TdmaMac(config, "auv2", LINK).capacity == 3


def test_a_packet_that_began_arriving_before_the_grant_ended_is_not_its_answer():
    lead, _ = pair(leader_packets=1)
    lead.carries = False
    assert lead.next_write_at(0.0) <= 0.0
    lead.parts(0.0)
    lead.wrote(0.0, 64)                              # the grant, 0.11 s on the air
    lead.arrived(64, 0.15)
    lead.heard(2, bytes([0x32]), 0.15)               # began at 0.04: a packet of an older turn
    assert lead.counts["ends_heard"] == 0 and lead.next_write_at(0.2) > 0.2


def _leader_packet(*kinds: int, control: bytes = b""):
    from uwgen.runtime.wire.envelope import Envelope
    from uwgen.runtime.wire.messages import Message
    return Envelope(sender=1, number=7, control=control or None,
                    messages=tuple(Message(kind=k, id=20, body=b"\x01") for k in kinds))


def test_a_follower_granted_with_a_request_keeps_its_turn_for_the_answer_being_built():
    """The request rode the grant's packet: the turn starts before the bridge has offered its
    answer. The first packet does not end the turn; the second carries the answer and the end."""
    _, follower = pair()
    follower.backlog = lambda now: False
    follower.hooks().received(_leader_packet(2, control=bytes([0x22, 2])), 1.0)  # request + grant
    assert follower.next_write_at(1.0) == -math.inf
    follower.offered(1.0, bytes.fromhex("000573"))      # a topic message meanwhile: not the answer
    assert write(follower, 1.0) == b""                  # no answer yet: the turn goes on
    follower.offered(1.05, bytes.fromhex("031419fb6f"))  # the bridge offers the answer
    follower.backlog = lambda now: True
    assert write(follower, 1.0 + follower.interval) == bytes([0x32])


def test_a_follower_whose_answer_was_offered_or_not_asked_for_ends_on_its_first_packet():
    _, answered = pair()
    answered.backlog = lambda now: False
    answered.hooks().received(_leader_packet(2), 0.5)   # a request, answered before the grant
    answered.offered(0.6, bytes.fromhex("031419fb6f"))
    answered.hooks().received(_leader_packet(control=bytes([0x22, 2])), 1.0)
    assert write(answered, 1.0) == bytes([0x32])
    _, topics = pair()
    topics.backlog = lambda now: False
    topics.hooks().received(_leader_packet(0, control=bytes([0x22, 2])), 1.0)   # a topic message
    assert write(topics, 1.0) == bytes([0x32])
