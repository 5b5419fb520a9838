"""TDMA writes timed to this side's slot (uwgen.runtime.link.slot_timing, TdmaMac): the
frame's phase learned from packets heard, writes placed before the ON window, and the rate
limit when no phase is known; explicit times (sans-IO, the link's clock)."""
from __future__ import annotations

import math

import pytest

from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac import TdmaMac, mac_for
from uwgen.runtime.link.slot_timing import (BLIND_FRAMES, LEAD, LISTEN_FRAMES, MEMORY_FRAMES, FramePhase,
                                            UNSAFE_BLIND_FRAMES, blind_frames, pair_gap,
                                            send_window)

LINK = LinkConfig(max_read_length=64, period=0.2)
# frame 1 s, 2 slots of 0.5 s, guard 0.25: surface ON [0, 0.25), vehicle ON [0.5, 0.75)
TWO = MacConfig(mode="tdma", frame=1.0, guard=0.25, slots=("surface", "vehicle"),
                max_packet_per_slot=1000, range=300)
# the same with guard 0.35 s: it covers a packet's air time and the range (blind_safe)
WIDE = MacConfig(mode="tdma", frame=1.0, guard=0.35, slots=("surface", "vehicle"),
                 max_packet_per_slot=1000, range=300)
SENDERS = {"surface": 1, "vehicle": 2}
AIR = (64 + 4) * 8 / 4800          # a full packet's air time
DELAY = 300 / 1500                 # propagation over the range


def arrival(origin: float, slot_start: float, place: float = 0.0, delay: float = DELAY,
            nbytes: int = 64) -> float:
    """When a packet sent `place` s into a slot starting at `slot_start` reaches the bridge."""
    return origin + slot_start + place + (nbytes + 4) * 8 / 4800 + delay


def hear(mac: TdmaMac, sender: int, at: float, nbytes: int = 64) -> None:
    mac.arrived(nbytes, at)
    mac.heard(sender, b"", at)


def test_the_frame_phase_is_learned_from_a_packet_heard():
    phase = FramePhase(TWO, {1: 0.0, 2: 0.5}, LINK)
    assert phase.start(0.0) is None
    phase.heard(2, 40, arrival(7.3, 0.5, nbytes=40))        # frames start at 7.3 + k
    assert phase.start(9.0) == pytest.approx(0.3)


def test_the_earliest_packet_of_a_slot_sets_the_phase_not_a_late_one():
    phase = FramePhase(TWO, {1: 0.0, 2: 0.5}, LINK)
    phase.heard(2, 64, arrival(10.3, 0.5, place=0.2))        # late in the window
    phase.heard(2, 64, arrival(11.3, 0.5, place=0.0))        # first in the window
    phase.heard(2, 64, arrival(12.3, 0.5, place=0.1))
    assert phase.start(13.0) == pytest.approx(0.3)


def test_the_phase_wraps_around_the_frame():
    # frames start at 0.95 (mod 1): marks land at 0.95 and at 0.05 (0.1 s into the window)
    phase = FramePhase(TWO, {1: 0.0, 2: 0.5}, LINK)
    phase.heard(2, 64, arrival(3.95, 0.5, place=0.1))
    phase.heard(2, 64, arrival(4.95, 0.5))
    assert phase.start(6.0) == pytest.approx(0.95)


def test_a_peer_nearer_than_the_range_makes_the_phase_early_never_late():
    phase = FramePhase(TWO, {1: 0.0, 2: 0.5}, LINK)
    phase.heard(2, 64, arrival(5.3, 0.5, delay=30 / 1500))   # 30 m away, range 300 m
    assert phase.start(6.0) == pytest.approx(0.3 - (300 - 30) / 1500)


def test_the_phase_is_taken_from_every_sides_slot():
    three = MacConfig(mode="tdma", frame=3.0, guard=0.2, slots=("surface", "auv1", "auv2"),
                      weights=(("surface", 2),), range=300)
    phase = FramePhase(three, {1: 0.0, 2: 1.5, 3: 2.25}, LINK)
    phase.heard(3, 64, arrival(20.4, 2.25))                  # auv1 silent: auv2 is enough
    assert phase.start(21.0) == pytest.approx(20.4 % 3.0)
    phase.heard(1, 64, arrival(23.4, 0.0, place=0.5))        # the surface's, later in its slot
    assert phase.start(24.0) == pytest.approx(20.4 % 3.0)


def test_a_guard_shorter_than_a_packet_and_the_range_shortens_the_send_window():
    # ON is 0.25 s, but a packet starting after 0.5 - 0.113 - 0.2 s reaches the far side
    # after the vehicle's slot has begun (half duplex: lost): 2 packets a slot, not 3
    assert send_window(TWO, LINK, "surface") == pytest.approx(0.5 - AIR - DELAY)
    assert TdmaMac(TWO, "surface", LINK).capacity == 2


def settled(mac: TdmaMac, at: float) -> float:
    """`mac` hears the vehicle's slot (2 packets) of the frame starting at `at`, frames
    starting at `at` + k: two packets of one sender a frame apart at most, so one was timed
    and the phase is settled. Returns the next frame's start."""
    hear(mac, 2, arrival(at, 0.5))
    hear(mac, 2, arrival(at, 0.5, place=AIR))
    return at + 1.0


def test_a_side_that_has_heard_nothing_listens_before_it_writes():
    # the guard (0.25 s) is shorter than a packet and the range (0.31 s): a packet written
    # blind may run into the next slot. The first slot's side listens LISTEN_FRAMES frames,
    # the others MEMORY_FRAMES: a side that starts late or restarts hears the others' timed
    # packets before it writes
    surface = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    vehicle = TdmaMac(TWO, "vehicle", LINK, senders=SENDERS)
    assert surface.next_write_at(3.0) == pytest.approx(3.0 + LISTEN_FRAMES * TWO.frame)
    assert vehicle.next_write_at(3.0) == pytest.approx(3.0 + MEMORY_FRAMES * TWO.frame)
    hear(vehicle, 1, arrival(4.0, 0.0, place=0.2))           # the surface's: now it knows a phase
    assert vehicle.next_write_at(4.6) < 3.0 + MEMORY_FRAMES * TWO.frame


def test_a_guard_covering_a_packet_and_the_range_lets_every_side_write_at_once():
    # guard 0.35 s >= 0.113 s of air + 0.2 s over 300 m: a packet DESERT starts anywhere in
    # ON ends before the next slot, so a side with no phase need not listen, whichever its
    # slot; still one packet per blind gap, the spacing the settling rule counts on
    assert send_window(WIDE, LINK, "vehicle") == pytest.approx(0.5 - 0.35)
    for side in WIDE.slots:
        mac = TdmaMac(WIDE, side, LINK, senders=SENDERS)
        assert mac.next_write_at(3.0) == -math.inf, side
        mac.wrote(3.0, 64)
        assert mac.next_write_at(3.3) == pytest.approx(3.0 + blind_frames(WIDE, LINK) * WIDE.frame), side


def test_with_no_phase_known_one_packet_goes_per_blind_gap():
    # it may start anywhere in DESERT's ON window and run into the next slot: one at a time,
    # until the answer it brings (the others' timed packets) has had time to arrive
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    t = mac.next_write_at(0.0)
    assert mac.next_write_at(t) == -math.inf
    mac.wrote(t, 64)
    assert mac.next_write_at(t + 0.21) == pytest.approx(t + blind_frames(TWO, LINK) * TWO.frame)
    assert mac.stats()["blind_writes"] == 1 and mac.stats()["timed_writes"] == 0


def test_a_phase_not_settled_has_writes_reach_the_mac_before_the_slot_even_if_it_is_late():
    # the packet heard may have started up to the vehicle's ON window (0.25 s) into it: the
    # frame then starts up to 0.25 s before 10.0 + k; until settled every write reaches
    # DESERT's MAC (a period after it) before the earliest opening, 11.75 + k, and after the
    # surface's window before closed
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    hear(mac, 2, arrival(10.0, 0.5))
    on = 0.5 - TWO.guard
    end = 12.0 - on - LEAD - 0.2
    t = mac.next_write_at(10.9)
    assert t == pytest.approx(max(12.0 - 1.0 + on, end - 0.21 - LEAD))
    for _ in range(2):
        assert mac.next_write_at(t) == -math.inf
        mac.wrote(t, 64)
        assert t + 0.2 + LEAD <= 12.0 - on                    # in the MAC before the earliest open
        t += 0.21
    assert mac.next_write_at(t) > 12.0                        # full: the next frame's
    # a second packet of the vehicle's within two frames: one of the two was timed
    hear(mac, 2, arrival(11.0, 0.5))
    close = 13.0 + send_window(TWO, LINK, "surface")
    begin = min(13.0 - 0.2 - LEAD, close - 0.2 - LEAD - 0.21 - LEAD)
    assert mac.next_write_at(12.2) == pytest.approx(begin)


def test_packets_of_one_sender_as_close_as_blind_writes_come_do_not_settle_the_phase():
    # guard 0.35 s covers a packet and the range: blind writes go three frames apart. The
    # first reached DESERT's MAC (a period after its write, 9.7) after the vehicle's ON window
    # [9.5, 9.65) closed and started at the next opening; the second, written as ON opened,
    # started at once and is shorter: they arrive two frames, less the air times' difference,
    # apart (closer than two frames, the gap the settling rule took before)
    phase = FramePhase(WIDE, {1: 0.0, 2: 0.5}, LINK)
    assert blind_frames(WIDE, LINK) == BLIND_FRAMES == 3
    phase.heard(2, 64, arrival(10.0, 0.5))                   # written at 9.5
    assert not phase.settled(11.0)
    phase.heard(2, 1, arrival(12.0, 0.5, nbytes=1))          # written at 12.5
    assert not phase.settled(12.9)
    phase.heard(1, 64, arrival(13.0, 0.0))                   # another sender's: no pair
    assert not phase.settled(13.5)
    phase.heard(2, 64, arrival(13.0, 0.5))                   # a frame after a timed one
    assert phase.settled(13.9)
    assert not phase.settled(13.9 + MEMORY_FRAMES)           # forgotten


def test_blind_writes_go_four_frames_apart_where_they_may_run_into_the_next_slot():
    # guard 0.25 s < 0.31 s of air and range: each blind write risks a side that has begun
    # to answer the one before, and the answer may take over three frames
    assert blind_frames(TWO, LINK) == UNSAFE_BLIND_FRAMES == 4
    # at most two frames there: a peer ticking slower must not have its blind packets taken
    # for a timed one, which would place writes late and into the next slot
    assert pair_gap(TWO, LINK) == pytest.approx(2 * TWO.frame)
    assert 2 * TWO.frame < 3 * TWO.frame - 0.2 - AIR - LEAD


def test_blind_writes_go_further_apart_when_a_frame_is_not_much_longer_than_a_period():
    # 3 frames of 0.4 s would bring two blind packets as close as timed ones a frame apart:
    # the settling rule could not tell them apart
    short = MacConfig(mode="tdma", frame=0.4, guard=0.15, slots=("surface", "vehicle"),
                      max_packet_per_slot=1000, range=10)
    assert pair_gap(short, LINK, 3) <= short.frame + AIR
    assert blind_frames(short, LINK) == 4
    assert pair_gap(short, LINK) > short.frame + AIR
    assert pair_gap(WIDE, LINK) == pytest.approx(2 * WIDE.frame - 0.2 - AIR - LEAD)


def test_writes_land_before_the_on_window_opens():
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    start = settled(mac, 10.0)                               # frames start at 10 + k
    # surface ON opens at start + 1: the first write goes a period and the lead before it,
    # or earlier so that the slot's 2 packets one interval apart all reach the MAC (a period
    # after their write) by the send window's close, with the lead to spare twice
    close = start + 1.0 + send_window(TWO, LINK, "surface")
    begin = min(start + 1.0 - 0.2 - LEAD, close - 0.2 - LEAD - 0.21 - LEAD)
    assert mac.next_write_at(start + 0.3) == pytest.approx(begin)
    t = mac.next_write_at(start + 0.3)
    timed = mac.stats()["timed_writes"]
    for _ in range(2):
        assert mac.next_write_at(t) == -math.inf
        mac.wrote(t, 64)
        assert t + 0.2 <= close - LEAD                       # in the MAC before the window closes
        t += 0.21
    assert mac.next_write_at(t) == pytest.approx(begin + 1.0)   # full: the next frame's
    assert mac.stats()["timed_writes"] == timed + 2


def test_writes_made_before_the_phase_was_known_count_in_the_first_window():
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    mac.wrote(10.8, 64)                                      # no phase: may wait for 12.0's ON
    hear(mac, 2, arrival(10.0, 0.5))
    t = mac.next_write_at(10.9)                              # settling window (11.25, 11.5)
    assert t == pytest.approx(11.25)
    mac.wrote(t, 64)
    assert mac.next_write_at(t + 0.21) == pytest.approx(t + 1.0)


def test_a_write_offered_late_in_the_window_still_goes_until_the_window_ends():
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    start = settled(mac, 10.0)
    end = start + 1.0 + send_window(TWO, LINK, "surface") - LEAD - 0.2
    assert mac.next_write_at(end - 0.01) == -math.inf
    assert mac.next_write_at(end + 0.01) > start + 1.5       # too late for this ON: next frame


def test_a_peer_silent_for_long_lets_tdma_write_without_a_phase():
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    hear(mac, 2, arrival(10.0, 0.5))
    assert mac.next_write_at(10.6) > 10.6                    # timed: waits for its window
    silent = 10.0 + 0.5 + AIR + DELAY + 10 * TWO.frame + 0.01
    assert mac.next_write_at(silent) == -math.inf            # phase forgotten, listened enough
    mac.wrote(silent, 64)
    assert mac.stats()["blind_writes"] == 1
    assert mac.next_write_at(silent + 0.3) == pytest.approx(silent + blind_frames(TWO, LINK) * TWO.frame)


def test_a_packet_from_a_sender_without_a_slot_teaches_nothing():
    mac = TdmaMac(TWO, "surface", LINK, senders=SENDERS)
    hear(mac, 9, 10.0)
    assert mac.phase.start(10.1) is None and mac.phase.ignored == 1


def test_without_senders_on_the_wire_a_packet_comes_from_the_only_other_side():
    mac = mac_for(TWO, "surface", SENDERS, LINK, wire_format=1)
    mac.arrived(None, arrival(10.0, 0.5))                    # no sender, size not known: a full packet
    assert mac.phase.start(10.9) == pytest.approx(0.0)
    assert mac.next_write_at(10.5) > 10.5


def test_a_tdma_link_writes_in_bursts_a_frame_apart_and_says_so():
    from uwgen.runtime.link.mac import Mac
    assert TdmaMac(TWO, "surface", LINK).burst == TWO.frame      # the scheduler's rate buckets
    assert Mac().burst == 0.0
