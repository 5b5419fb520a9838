"""When a command's copy is due (uwgen.bridge.copies): never while an equal payload still
waits in the link; under the turns MAC once per round, when the own turn that carried it has
ended (whatever became of it there: lost, or delivered and refused by the receiving judge);
under TDMA once a frame, when the answer to its last departure could no longer come;
otherwise on its timer."""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

from uwgen.bridge.copies import answer_time, copy_due, own_turns
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
    answer_by: float | None = None


def link(turns=None, answer_by=lambda now: None):
    """A wiring's view of the link: what waits in it, the own turns ended, and when the
    answers to a message leaving now are in (TDMA)."""
    state = SimpleNamespace(waiting=set(), turns=turns)
    return state, SimpleNamespace(waiting=lambda k, p: (k, p) in state.waiting,
                                  turns=lambda: state.turns, answer_by=answer_by)


def test_without_turns_a_copy_is_due_on_its_timer():
    _, w = link()
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 20, b"req", leg, 2.9, rto=3.0)
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0)


def test_without_turns_a_copy_whose_message_still_waits_in_the_link_is_put_off_a_timeout():
    state, w = link()
    state.waiting.add((20, b"req"))
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 20, b"req", leg, 3.0, rto=2.5)
    assert leg.next_send == 5.5
    state.waiting.clear()
    assert not copy_due(w, 20, b"req", leg, 5.0, rto=2.5)
    assert copy_due(w, 20, b"req", leg, 5.5, rto=2.5)


def test_under_turns_a_copy_is_due_once_the_turn_that_carried_it_has_ended_not_on_a_timer():
    state, w = link(turns=7)
    leg = Leg(next_send=0.0, turn=7)                 # offered in turn 7: its timer is no matter
    assert not copy_due(w, 20, b"req", leg, 100.0, rto=3.0)
    state.turns = 8                                   # that turn ended: the peer's turn now
    assert copy_due(w, 20, b"req", leg, 100.0, rto=3.0)
    assert not copy_due(w, 20, b"req", leg, 100.0, rto=3.0)   # once a round
    state.turns = 9
    assert copy_due(w, 20, b"req", leg, 100.0, rto=3.0)


def test_a_request_delivered_but_refused_there_unanswered_is_copied_the_next_round():
    # A request that arrived and was refused by the receiving judge (`unmeasured` before the
    # clock exchange, `stale`, `untimed`) gets no answer: whether its packet was acknowledged
    # does not matter, the round without an answer makes its copy due.
    state, w = link(turns=0)
    leg = Leg(turn=0)
    state.turns = 1
    assert copy_due(w, 20, b"req", leg, 1.0, rto=3.0)


def test_under_turns_a_message_that_missed_its_turn_is_copied_a_round_after_it_leaves():
    state, w = link(turns=3)
    state.waiting.add((20, b"req"))                  # the turn was full: it waits for the next
    leg = Leg(turn=3)
    state.turns = 4
    assert not copy_due(w, 20, b"req", leg, 1.0, rto=3.0)
    assert leg.turn == 4
    state.waiting.clear()                            # it left in the turn that ends with 5
    assert not copy_due(w, 20, b"req", leg, 2.0, rto=3.0)
    state.turns = 5
    assert copy_due(w, 20, b"req", leg, 3.0, rto=3.0)


def test_under_tdma_a_copy_is_due_once_the_answer_to_its_slot_could_no_longer_come():
    # frames of 3 s; a message that leaves in the ON window opening at 3k has its answers in
    # by 3k + 2.98 (TdmaMac.answer_by), before the next window's writes end
    state, w = link(answer_by=lambda now: 3.0 * ((now + 0.9) // 3.0) + 2.98)
    state.waiting.add((20, b"req"))
    leg = Leg(next_send=2.5)                          # offered at -0.7 with a 3.2 s timer
    assert not copy_due(w, 20, b"req", leg, -0.6, rto=3.2)
    state.waiting.clear()                             # written at -0.5 for the ON at 0
    assert not copy_due(w, 20, b"req", leg, -0.45, rto=3.2)
    assert not copy_due(w, 20, b"req", leg, 2.6, rto=3.2)    # the timer's copy: answer not in yet
    assert copy_due(w, 20, b"req", leg, 2.98, rto=3.2)
    state.waiting.add((20, b"req"))                   # the copy waits for the next window
    assert not copy_due(w, 20, b"req", leg, 3.0, rto=3.2)
    state.waiting.clear()                             # left for the ON at 3
    assert not copy_due(w, 20, b"req", leg, 3.1, rto=3.2)
    assert not copy_due(w, 20, b"req", leg, 5.9, rto=3.2)
    assert copy_due(w, 20, b"req", leg, 5.98, rto=3.2)


def test_under_tdma_without_a_phase_a_copy_is_due_on_its_timer():
    _, w = link(answer_by=lambda now: None)
    leg = Leg(next_send=3.0)
    assert not copy_due(w, 20, b"req", leg, 2.9, rto=3.0)
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


def test_answer_time_is_the_tdma_macs_and_none_under_other_macs():
    tdma = TdmaMac(MacConfig(mode="tdma", frame=3.0, guard=0.8, slots=("surface", "vehicle")),
                   "surface", LINK, senders=SENDERS)
    assert answer_time(tdma) == tdma.answers.answer_by
    assert answer_time(Mac())(5.0) is None
    assert answer_time(TurnMac(TURNS, "surface", SENDERS, LINK))(5.0) is None


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


def test_results_arriving_together_are_acknowledged_once_while_the_ack_still_waits():
    # two copies of one result heard from one slot: one acknowledgement, not two in a packet
    from uwgen.bridge.action_answers import GoalAnswers, GoalState
    from uwgen.bridge.calls import CallTable
    from uwgen.bridge.counters import ActionCounters
    from uwgen.runtime.wire.table import RESULTS
    queued = []
    w = Wiring(node=None, send=lambda k, p: queued.append((k, p)) or True, clock=ManualClock(),
               options=None, log=SimpleNamespace(error=print, warning=print), main_group=None,
               service_group=None)
    w.waiting = lambda k, p: (k, p) in queued
    codec = SimpleNamespace(decode_response=lambda p: (p[2], next(iter(RESULTS)), "result"),
                            encode_result_status=lambda h, received: bytes([2, 9, 0x18, h, 0]))
    answers = GoalAnswers()
    table = CallTable(w.clock, seq_modulus=256)
    answers.w, answers.offered, answers.counters = w, {9: codec}, {9: ActionCounters()}
    answers.tables, answers.handles = {9: table}, {9: range(0, 256)}
    pending = table.begin(9, 30.0)
    pending.token = GoalState(ident=9, handle=pending.seq, request=None)
    result = bytes([3, 9, pending.seq, 4])
    answers.on_response(9, result)
    answers.on_response(9, result)                    # its copy, from the same slot
    assert queued == [(9, bytes([2, 9, 0x18, pending.seq, 0]))]
    queued.clear()                                    # the ack left: a later copy means it was lost
    answers.on_response(9, result)
    assert queued == [(9, bytes([2, 9, 0x18, pending.seq, 0]))]
