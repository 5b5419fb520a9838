"""When a command's copy is due (uwgen.bridge.copies): never while an equal payload still
waits in the link; under the turns MAC by the round, as the peer's report told its fate: at
once when told lost, not when told arrived, a round later when nothing was told (unless
urgent), every round once it was told arrived (delivered and refused by the receiving judge,
or its answer lost again); otherwise on its timer."""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

from uwgen.bridge.copies import copy_due, own_turns
from uwgen.bridge.fates import Fates
from uwgen.bridge.wiring import Wiring
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.mac import Mac, TdmaMac, TurnMac

LINK = LinkConfig(max_read_length=64, period=0.2)
SENDERS = {"surface": 1, "vehicle": 2}
TURNS = MacConfig(mode="turns", range=1000, leader="surface", packets=(("surface", 4), ("vehicle", 2)))


@dataclass
class Leg:
    next_send: float = 3.0
    turn: int | None = None
    held: bool = False


def link(turns=None):
    """A wiring's view of the link: what waits in it, the own turns ended, the fates told,
    and urgency (fewer than 7 s left: 2.5 rounds of 2.8 s)."""
    state = SimpleNamespace(waiting=set(), turns=turns, now=0.0)
    fates = Fates(ManualClock(), withdraw=lambda k, p: False, offer_again=lambda k, p, until: True)
    return state, SimpleNamespace(waiting=lambda k, p: (k, p) in state.waiting,
                                  turns=lambda: state.turns, fates=fates, turn_gap=0.0,
                                  urgent=lambda deadline, answer=False: deadline - state.now < 7.0)


def test_without_turns_a_copy_is_due_on_its_timer():
    _, w = link()
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 20, b"req", leg, 2.9, rto=3.0, deadline=12.0)
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0, deadline=12.0)


def test_without_turns_a_result_with_nothing_told_waits_one_more_timeout_once():
    _, w = link()
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 9, b"result", leg, 3.0, rto=3.0)          # its report was lost
    assert leg.held and leg.next_send == 6.0
    assert not copy_due(w, 9, b"result", leg, 5.9, rto=3.0)
    assert copy_due(w, 9, b"result", leg, 6.0, rto=3.0)              # still nothing: the copy
    leg.next_send = 12.0
    assert copy_due(w, 9, b"result", leg, 12.0, rto=6.0)             # held once only


def test_on_a_timer_a_request_with_nothing_told_is_not_held_a_standing_in_result_is_until_urgent():
    state, w = link()
    w.turn_gap = 3.0                                  # a TDMA frame
    leg = Leg(next_send=3.0)
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0, deadline=12.0) and not leg.held
    standing = Leg(next_send=3.0)                     # 9 s left on its goal's answer: held
    assert not copy_due(w, 9, b"result", standing, 3.0, rto=3.0, deadline=12.0, answer=True)
    late = Leg(next_send=3.0)
    state.now = 6.0                                   # 6 s left: urgent, not held
    assert copy_due(w, 9, b"result", late, 6.0, rto=3.0, deadline=12.0, answer=True)


def test_without_turns_a_result_told_lost_is_not_held():
    _, w = link()
    leg = Leg(next_send=3.0)
    w.fates.told(9, b"result", False)
    assert copy_due(w, 9, b"result", leg, 1.0, rto=3.0) and not leg.held


def test_without_turns_a_copy_whose_message_still_waits_in_the_link_is_put_off_a_timeout():
    state, w = link()
    state.waiting.add((20, b"req"))
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 20, b"req", leg, 3.0, rto=2.5, deadline=12.0)
    assert leg.next_send == 5.5
    state.waiting.clear()
    assert not copy_due(w, 20, b"req", leg, 5.0, rto=2.5, deadline=12.0)
    assert copy_due(w, 20, b"req", leg, 5.5, rto=2.5, deadline=12.0)


def test_under_turns_a_copy_told_lost_is_due_once_its_turn_has_ended_not_on_a_timer():
    state, w = link(turns=7)
    leg = Leg(next_send=0.0, turn=7)                 # offered in turn 7: its timer is no matter
    w.fates.told(20, b"req", arrived=False)
    assert not copy_due(w, 20, b"req", leg, 100.0, rto=3.0)   # that turn has not ended
    state.turns = 8
    assert copy_due(w, 20, b"req", leg, 100.0, rto=3.0)
    assert not copy_due(w, 20, b"req", leg, 100.0, rto=3.0)   # once a round


def test_under_turns_a_copy_told_arrived_is_spared():
    state, w = link(turns=7)
    leg = Leg(turn=7)
    state.turns = 8
    w.fates.told(20, b"req", arrived=True)
    assert not copy_due(w, 20, b"req", leg, 1.0, rto=3.0)


def test_under_turns_with_nothing_told_the_copy_waits_a_round_for_the_next_report():
    # the peer's report rode a packet that was lost: the request arrived four times in five,
    # and the peer's next report names it again
    state, w = link(turns=7)
    leg = Leg(turn=7)
    state.turns = 8
    assert not copy_due(w, 20, b"req", leg, 1.0, rto=3.0, deadline=20.0)
    state.turns = 9                                   # the next round told nothing either
    assert copy_due(w, 20, b"req", leg, 4.0, rto=3.0, deadline=20.0)


def test_under_turns_a_result_with_nothing_told_waits_two_rounds_for_the_peers_news():
    state, w = link(turns=7)
    leg = Leg(turn=7)
    for turns in (8, 9):                              # the report lost, and none since
        state.turns = turns
        assert not copy_due(w, 9, b"result", leg, 1.0, rto=3.0)
    state.turns = 10
    assert copy_due(w, 9, b"result", leg, 1.0, rto=3.0)


def test_under_turns_an_urgent_command_with_nothing_told_is_copied_at_once():
    state, w = link(turns=7)
    leg = Leg(turn=7)
    state.turns, state.now = 8, 6.0
    assert copy_due(w, 20, b"req", leg, 6.0, rto=3.0, deadline=12.0)


def test_a_request_delivered_but_refused_there_unanswered_is_copied_every_round_but_one():
    # A request that arrived and was refused by the receiving judge (`unmeasured` before the
    # clock exchange, `stale`, `untimed`) gets no answer: its arrival spares one copy, then
    # a round without an answer makes the copy due, as does each round after.
    state, w = link(turns=0)
    leg = Leg(turn=0)
    w.fates.told(20, b"req", arrived=True)
    state.turns = 1
    assert not copy_due(w, 20, b"req", leg, 1.0, rto=3.0, deadline=20.0)
    state.turns = 2
    assert copy_due(w, 20, b"req", leg, 2.0, rto=3.0, deadline=20.0)
    state.turns = 3
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0, deadline=20.0)


def test_under_turns_a_message_that_missed_its_turn_is_copied_a_round_after_it_leaves():
    state, w = link(turns=3)
    state.waiting.add((20, b"req"))                  # the turn was full: it waits for the next
    leg = Leg(turn=3)
    state.turns = 4
    assert not copy_due(w, 20, b"req", leg, 1.0, rto=3.0)
    assert leg.turn == 4
    state.waiting.clear()                            # it left in the turn that ends with 5
    assert not copy_due(w, 20, b"req", leg, 2.0, rto=3.0)
    w.fates.told(20, b"req", arrived=False)
    state.turns = 5
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0)


def test_own_turns_are_the_leaders_grants_and_a_followers_ends_and_none_without_turns():
    leader, follower = (TurnMac(TURNS, s, SENDERS, LINK) for s in ("surface", "vehicle"))
    leader.counts["grants_sent"], follower.counts["turns"] = 3, 5
    assert (own_turns(leader)(), own_turns(follower)()) == (3, 5)
    leader.counts["grants_sent"] += 1
    assert own_turns(leader)() == 4
    tdma = MacConfig(mode="tdma", frame=3.0, guard=0.8, slots=("surface", "vehicle"))
    assert own_turns(Mac())() is None
    assert own_turns(TdmaMac(tdma, "surface", LINK, senders=SENDERS))() is None


def test_offer_once_queues_nothing_while_an_equal_payload_still_waits():
    sent = []
    w = Wiring(node=None, send=lambda k, p: sent.append((k, p)) or True, clock=ManualClock(), options=None,
               log=SimpleNamespace(error=print, warning=print), main_group=None, service_group=None)
    w.waiting = lambda k, p: (k, p) == (20, b"old")
    assert w.offer_once(20, b"old") and w.offer_once(20, b"new")
    assert sent == [(20, b"new")]


def test_an_arriving_answer_takes_its_copy_back_on_the_link_thread_and_only_its_own():
    taken = []
    w = Wiring(node=None, send=lambda k, p: True, clock=ManualClock(), options=None,
               log=SimpleNamespace(error=print, warning=print), main_group=None, service_group=None)
    w.withdraw = lambda k, p: taken.append((k, p)) or True
    w.expect(b"\x03\x14\x05", 20, b"\x02\x14\x05req")
    w.expect(b"\x03\x14\x06", 20, b"\x02\x14\x06req")
    w.take_back(b"\x03\x14\x05resp")
    assert taken == [(20, b"\x02\x14\x05req")]
    w.take_back(b"\x03\x14\x05resp")                 # a second answer: nothing left to take
    assert taken == [(20, b"\x02\x14\x05req")] and list(w.answered_by) == [b"\x03\x14\x06"]


def test_a_message_awaiting_its_answer_told_lost_is_offered_at_once_under_turns_only():
    for turns, offered in ((3, [(20, b"req", 40.0)]), (None, [])):
        sent = []
        w = Wiring(node=None, send=lambda k, p, published=None: sent.append((k, p, published)) or True,
                   clock=ManualClock(),
                   options=None, log=SimpleNamespace(error=print, warning=print), main_group=None,
                   service_group=None)
        w.turns = lambda: turns
        w.withdraw = lambda k, p: sent.remove((k, p, 40.0)) is None
        # its age item counts from its call's start, as every copy's
        w.fates.awaiting(20, b"req", 12.0, lambda: True, b"\x03\x14\x07", published=40.0)
        w.fates.told(20, b"req", arrived=False)
        assert sent == offered
        assert w.fates.lost(20, b"req") == (turns is None)       # a timer sends it then
        if turns is not None:
            w.take_back(b"\x03\x14\x07resp")                   # its answer takes it back
            assert sent == []
