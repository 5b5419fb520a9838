"""A round as a side lives it (uwgen.runtime.link.turn_timing.Rounds, Mac.round) and the
bridge's urgency counted in it (uwgen.bridge.wiring.Wiring.urgent), with explicit times."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.mac import TdmaMac, TurnMac
from uwgen.runtime.link.turn_timing import ROUNDS_NEEDED, Rounds

LINK = LinkConfig(max_read_length=64, period=0.2)
SENDERS = {"surface": 1, "vehicle": 2}


def test_a_round_is_measured_only_after_enough_own_turns():
    rounds = Rounds()
    for k in range(ROUNDS_NEEDED):
        rounds.started(2.5 * k)
        assert rounds.measured() is None             # fewer spacings than needed
    rounds.started(2.5 * ROUNDS_NEEDED)
    assert rounds.measured() == pytest.approx(2.5)


def test_a_turn_lost_now_and_then_does_not_lengthen_the_round():
    rounds = Rounds()
    for start in (0.0, 2.5, 5.0, 10.0, 12.5, 15.0):  # the turn due at 7.5 was lost
        rounds.started(start)
    assert rounds.measured() == pytest.approx(2.5)


def test_a_leaders_round_is_its_bound_until_measured_then_the_spacing_of_its_turns():
    turns = MacConfig(mode="turns", range=1000, leader="surface",
                      packets=(("surface", 1), ("vehicle", 2)))
    lead = TurnMac(turns, "surface", SENDERS, LINK)
    lead.backlog = lambda now: False
    bound = lead.turn_gap()

    def turn(t: float) -> None:
        assert lead.next_write_at(t) <= t
        lead.parts(t)                                # its one packet: the grant
        lead.wrote(t, 20)
        lead.heard(2, bytes([0x32]), t + 1.4)        # the vehicle's end: the turn is back

    for k in range(ROUNDS_NEEDED):
        turn(1.9 * k)
    assert lead.round() == lead.turn_gap()           # not enough turns yet: the bound
    turn(1.9 * ROUNDS_NEEDED)
    assert bound > 2.5                               # the first bound counts a worst case
    assert lead.round() == pytest.approx(1.9)        # the rounds lived were shorter


def test_a_tdma_round_is_its_frame():
    tdma = MacConfig(mode="tdma", frame=3.0, guard=0.5, slots=("surface", "vehicle"))
    assert TdmaMac(tdma, "surface", LINK, senders=SENDERS).round() == 3.0


def test_a_message_offered_between_own_turns_leaves_a_round_after_the_last_began():
    turns = MacConfig(mode="turns", range=1000, leader="surface",
                      packets=(("surface", 1), ("vehicle", 2)))
    lead = TurnMac(turns, "surface", SENDERS, LINK)
    lead.backlog = lambda now: False
    assert lead.next_turn(0.0) == 0.0                # it holds its turn: now
    for k in range(ROUNDS_NEEDED + 1):               # rounds of 1.9 s measured
        lead.parts(1.9 * k)
        lead.wrote(1.9 * k, 20)
        if k < ROUNDS_NEEDED:
            lead.heard(2, bytes([0x32]), 1.9 * k + 1.4)
    last = 1.9 * ROUNDS_NEEDED                       # its last turn began then, and ended
    assert lead.next_turn(last + 0.5) == pytest.approx(last + 1.9)
    assert lead.next_turn(last + 2.5) == last + 2.5  # overdue (the follower's turn is long)


def _urgent(left: float, measured: float | None, answer: bool = False,
            leaves_in: float = 0.0) -> bool:
    from uwgen.bridge.wiring import Wiring
    clock = ManualClock(100.0)
    w = SimpleNamespace(clock=clock, turn_gap=3.3,
                        measured_round=None if measured is None else (lambda: measured),
                        next_turn=lambda now: now + leaves_in)
    return Wiring.urgent(w, 100.0 + left, answer)


def test_a_commands_rounds_left_are_counted_in_the_measured_round_not_the_bound():
    from uwgen.bridge.wiring import ANSWER_URGENT_ROUNDS, URGENT_ROUNDS
    left = URGENT_ROUNDS * 2.5 + 0.5                 # 3 rounds of 2.5 s, under 2.5 of 3.3 s
    assert _urgent(left, measured=None)              # counted in the bound: urgent
    assert not _urgent(left, measured=2.5)           # in the rounds lived: a repair alone
    assert _urgent(URGENT_ROUNDS * 2.5 - 0.1, measured=2.5)
    assert not _urgent(ANSWER_URGENT_ROUNDS * 2.5 + 0.1, measured=2.5, answer=True)
    assert _urgent(ANSWER_URGENT_ROUNDS * 2.5 - 0.1, measured=2.5, answer=True)


def test_a_commands_rounds_left_are_counted_from_when_it_can_leave():
    from uwgen.bridge.wiring import URGENT_ROUNDS
    left = URGENT_ROUNDS * 2.5 + 1.0                 # more rounds than urgent, counted from now
    assert not _urgent(left, measured=2.5)
    assert _urgent(left, measured=2.5, leaves_in=2.0)   # offered as its turn ended: a round on
