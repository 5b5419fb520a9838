"""Each side repairs its own leg from the fates the peer's reports tell (uwgen.bridge.fates;
docs/wire-format.md section 15.6, "A command's fate"): a copy of a message that arrived is
taken back or spared once; a lost answer goes again at once from the side that has it; a
lost request's copy is due at once on a timer."""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

from uwgen.bridge.copies import copy_due
from uwgen.bridge.fates import Fates
from uwgen.runtime.clock import ManualClock

CALL = 20
REQUEST = bytes((2, CALL, 7, 1))
RESPONSE = bytes((3, CALL, 7, 3))
ANSWER = RESPONSE[:3]


@dataclass
class Leg:
    next_send: float = 3.0
    turn: int | None = None
    held: bool = False


def wired(turns=None):
    """Fates over a link's queue (`waiting`: what waits in it) and the own turns ended."""
    clock = ManualClock()
    state = SimpleNamespace(waiting=set(), turns=turns, offered=[])

    def withdraw(key, payload):
        if (key, payload) in state.waiting:
            state.waiting.discard((key, payload))
            return True
        return False

    def offer_again(key, payload, until):
        state.offered.append((key, payload))
        return True
    fates = Fates(clock, withdraw, offer_again)
    w = SimpleNamespace(waiting=lambda k, p: (k, p) in state.waiting, turns=lambda: state.turns,
                        fates=fates)
    return state, w, clock


def test_an_arrival_takes_back_the_copy_waiting_in_the_link():
    state, w, _ = wired(turns=3)
    state.waiting.add((CALL, REQUEST))               # the copy offered as its turn ended
    w.fates.told(CALL, REQUEST, True)                # the peer's report: the first arrived
    assert state.waiting == set() and w.fates.stats()["spared"] == 1


def test_an_arrival_told_before_the_copy_falls_due_spares_one_copy_only():
    state, w, _ = wired(turns=3)
    leg = Leg(turn=3)
    w.fates.told(CALL, REQUEST, True)
    state.turns = 4
    assert not copy_due(w, CALL, REQUEST, leg, 10.0, rto=3.0)   # the peer has it
    state.turns = 5                                             # a round without the answer
    assert copy_due(w, CALL, REQUEST, leg, 20.0, rto=3.0)       # sent again: the fallback


def test_on_a_timer_a_lost_request_is_due_at_once_and_an_arrived_one_waits_a_timeout():
    _, w, _ = wired()
    leg = Leg(next_send=3.0)
    assert not copy_due(w, CALL, REQUEST, leg, 1.0, rto=3.0)
    w.fates.told(CALL, REQUEST, False)
    assert copy_due(w, CALL, REQUEST, leg, 1.0, rto=3.0)        # not at 3.0
    w.fates.told(CALL, REQUEST, True)                           # its copy arrived
    assert not copy_due(w, CALL, REQUEST, leg, 3.0, rto=3.0) and leg.next_send == 6.0


def test_a_lost_answer_is_offered_again_until_its_callers_deadline():
    state, w, clock = wired()
    w.fates.repairable(CALL, RESPONSE, until=12.0)
    w.fates.told(CALL, RESPONSE, False)
    assert state.offered == [(CALL, RESPONSE)] and w.fates.stats()["repaired"] == 1
    clock.advance(12.0)
    w.fates.told(CALL, RESPONSE, False)                         # too late: the call is over
    assert state.offered == [(CALL, RESPONSE)]


def test_an_answer_that_arrived_is_not_repaired_when_another_copy_is_lost():
    state, w, _ = wired()
    w.fates.repairable(CALL, RESPONSE, until=12.0)
    w.fates.told(CALL, RESPONSE, True)
    w.fates.told(CALL, RESPONSE, False)                         # its repeat's packet, lost
    assert state.offered == []


def test_a_message_nobody_registered_is_not_offered_again_when_lost():
    state, w, _ = wired()
    w.fates.told(CALL, REQUEST, False)                          # a request: its leg copies it
    assert state.offered == [] and w.fates.stats()["lost"] == 1


# -- two links under turns (a ManualClock): the vehicle's answer is lost ----------------------

def answer_lost_over_turns(fates_on: bool, report_lost: bool = False, twice: bool = False):
    """A call at 5 s over turns at 1000 m whose first answer packet is lost (`report_lost`:
    and the surface's first packet with a report after it; `twice`: the surface's reports
    telling a loss ride its next packet too). Returns the times the vehicle wrote the
    answer, the times the surface wrote the request, and when the answer reached the
    surface (None: not by 20 s)."""
    from tests.runtime.turns_pair import SENDERS, turns_pair
    from uwgen.manifest.model import LinkPolicy

    def settle(rel) -> None:
        for _ in range(64):
            rel.engine.spare.settled(True)               # no loss measured: no copies in turn
    sim, clock, rel = turns_pair(frozenset({CALL}), {}, settle)
    rel["surface"].acks.twice = twice
    wrote: dict[str, list[float]] = {s: [] for s in SENDERS}
    reports = {"bytes": 0, "lost": not report_lost}
    for side, link in sim.links.items():
        sent = link.hooks.sent

        def spy(number, picked, now, side=side, sent=sent):
            if side == "surface" and wrote["vehicle"] and not reports["lost"] \
                    and rel[side].report_bytes > reports["bytes"]:
                sim.drop(side, sim.written[side])            # the report on that answer: lost
                reports["lost"] = True
            reports["bytes"] = rel["surface"].report_bytes
            if any(key == CALL for key, _ in picked):
                if side == "vehicle" and not wrote[side]:
                    sim.drop(side, sim.written[side])        # the first answer is lost
                wrote[side].append(now)
            return sent(number, picked, now)
        link.hooks.sent = spy
        link.add_channel(CALL, LinkPolicy(queue="fifo", depth=8, ttl=12.0))
    vehicle = Fates(clock, withdraw=sim.links["vehicle"].scheduler.withdraw,
                    offer_again=lambda k, p, until: sim.links["vehicle"].offer(k, p))
    if fates_on:
        rel["vehicle"].on_fate = vehicle.told
    sim.at(5.0, lambda: sim.links["surface"].offer(CALL, REQUEST))
    state = {"answered": False, "back": None}

    def serve():                                # the vehicle's bridge answers once
        if not state["answered"] and any(p == REQUEST for _, p in sim.received["vehicle"]):
            state["answered"] = True
            sim.links["vehicle"].offer(CALL, RESPONSE)
            vehicle.repairable(CALL, RESPONSE, until=clock.now() + 12.0)
        if state["back"] is None and any(p == RESPONSE for _, p in sim.received["surface"]):
            state["back"] = clock.now()
    for k in range(400):
        sim.at(0.05 * k, serve)
    sim.run(20.0)
    return wrote["vehicle"], wrote["surface"], state["back"], vehicle


def test_under_turns_a_lost_answer_goes_again_in_the_next_turn_without_the_request_again():
    answers, requests, back, fates = answer_lost_over_turns(fates_on=True)
    assert len(requests) == 1                        # the caller sent nothing again
    assert len(answers) == 2 and back is not None    # the vehicle repaired its own leg
    assert fates.stats()["repaired"] == 1


def test_under_turns_a_lost_answer_told_by_the_leaders_second_report_goes_again_next_turn():
    # the surface's report telling the answer lost rides its first packet, which is lost too:
    # said again on its next packet (a notice), the vehicle still repairs in its next turn
    answers, requests, back, fates = answer_lost_over_turns(True, report_lost=True, twice=True)
    assert len(requests) == 1 and len(answers) == 2 and back is not None
    once = answer_lost_over_turns(True, report_lost=True, twice=False)
    assert once[2] is None or once[2] > back + 1.5   # said once: a round later, if at all


def test_without_fates_a_lost_answer_waits_for_a_copy_of_the_request():
    answers, requests, back, _ = answer_lost_over_turns(fates_on=False)
    assert len(answers) == 1 and back is None        # nobody sends anything again here


def test_a_command_sent_again_gets_its_copy_in_turn_only_in_its_last_rounds():
    from uwgen.bridge.wiring import URGENT_ROUNDS, Wiring
    clock = ManualClock(100.0)
    w = SimpleNamespace(clock=clock, turn_gap=3.0, measured_round=None, next_turn=lambda now: now)
    urgent = lambda deadline: Wiring.urgent(w, deadline)      # noqa: E731
    assert not urgent(100.0 + URGENT_ROUNDS * 3.0)           # rounds left for a repair alone
    assert urgent(100.0 + URGENT_ROUNDS * 3.0 - 0.1)
    w.turn_gap = 0.0                                          # no MAC: no turn to copy in
    assert not urgent(100.5)


def test_an_answer_given_again_gets_its_copy_in_turn_only_in_the_calls_last_round():
    from uwgen.bridge.wiring import ANSWER_URGENT_ROUNDS, URGENT_ROUNDS, Wiring
    clock = ManualClock(100.0)
    w = SimpleNamespace(clock=clock, turn_gap=3.0, round_trip=1.0, measured_round=None,
                        next_turn=lambda now: now)
    w.urgent = lambda deadline, answer=False: Wiring.urgent(w, deadline, answer)  # noqa: E731
    w.callers_deadline = Wiring.callers_deadline
    assert ANSWER_URGENT_ROUNDS < URGENT_ROUNDS              # the answer's own leg is the last
    left = (ANSWER_URGENT_ROUNDS + URGENT_ROUNDS) / 2 * 3.0   # a round to repair its loss, and more
    assert Wiring.urgent(w, 100.0 + left)                     # a request's copy: urgent
    assert not Wiring.urgent(w, 100.0 + left, answer=True)    # an answer: goes alone
    assert Wiring.urgent(w, 100.0 + ANSWER_URGENT_ROUNDS * 3.0 - 0.1, answer=True)
    # a 12 s call that began at 94 ends at 106, 6 s (2 rounds) from now
    assert not Wiring.answer_urgent(w, 94.0, 12.0)
    assert Wiring.answer_urgent(w, 92.0, 12.0)               # 4 s left: under 2 rounds


def _wiring(began_at=None):
    from uwgen.bridge.wiring import Wiring
    sent = []
    w = Wiring(node=None, send=lambda k, p, published=None: sent.append((k, p)) or True,
               clock=ManualClock(100.0), options=None,
               log=SimpleNamespace(error=print, warning=print), main_group=None,
               service_group=None, turn_gap=3.0, round_trip=1.4)
    if began_at is not None:
        w.began_at = began_at
    return w, sent


def test_without_an_age_item_the_serving_side_counts_from_before_the_request_came():
    w, _ = _wiring()
    # it came about half a round (its wait for its turn) and a trip after the call began
    assert w.began(REQUEST, 50.0) == 50.0 - (3.0 + 1.4) / 2
    w.round_trip = None                                       # no MAC figure: the turn alone
    assert w.began(REQUEST, 50.0) == 50.0 - 1.5
    assert w.callers_deadline(48.5, 12.0) == 60.5


def test_the_serving_side_times_its_callers_deadline_on_the_age_item_of_the_copy_that_came():
    # the request's first two copies were lost: the copy that came at 50 says (its age
    # item, every copy carrying its call's) that the call began 7.4 s before
    w, _ = _wiring(began_at=lambda payload: 42.6 if payload == REQUEST else None)
    assert w.began(REQUEST, 50.0) == 42.6
    assert w.callers_deadline(w.began(REQUEST, 50.0), 12.0) == 42.6 + 12.0    # not 59.8
    assert w.began(bytes((2, CALL, 8, 1)), 50.0) == 50.0 - (3.0 + 1.4) / 2   # not kept: as before


class _Done:
    """A local call's future, answered."""

    def __init__(self, result):
        self._result = result

    def add_done_callback(self, cb):
        self.cb = cb

    def cancelled(self):
        return False

    def exception(self):
        return None

    def result(self):
        return self._result


def _server(w):
    """The serving side of /echo (id 20, timeout 12 s) over `w`, its local server a fake."""
    from uwgen.bridge.service_servers import Servers
    codec = SimpleNamespace(id=CALL, name="/echo", timeout=12.0, type_name="t",
                            decode_request=lambda p: (p[2], "request"),
                            encode_response=lambda seq, r: bytes((3, CALL, seq, 3)))
    calls = []
    client = SimpleNamespace(service_is_ready=lambda: True,
                             call_async=lambda request: calls.append(_Done("reply")) or calls[-1])
    w.ros_class = lambda codec, kind: object
    w.node = SimpleNamespace(create_client=lambda *a, **k: client)
    w.loops = SimpleNamespace(watch_server=lambda name: None, blocked=lambda name: False)
    return Servers(w, [codec], {}), calls


def test_the_response_to_a_request_that_came_late_gets_its_copy_in_its_turn_from_the_first():
    repeated = []
    # came at 100, its call began 7.5 s before (two rounds lost): 4.5 s, under 2 rounds, left
    w, sent = _wiring(began_at=lambda payload: 92.5)
    w.repeat = lambda key, payload: repeated.append((key, payload))
    servers, calls = _server(w)
    servers.serve(CALL, REQUEST + b"\x00")
    calls[-1].cb(calls[-1])                                   # the local server answered
    assert sent == [(CALL, RESPONSE)] and repeated == [(CALL, RESPONSE)]
    # its repair, told lost, goes until the caller's real deadline, not a round later
    w.clock.set(104.4)
    w.fates.told(CALL, RESPONSE, False)
    assert sent[-1] == (CALL, RESPONSE) and len(sent) == 2
    w.clock.set(104.6)
    w.fates.told(CALL, RESPONSE, False)
    assert len(sent) == 2


def test_the_response_to_a_request_that_came_in_its_first_round_goes_alone():
    repeated = []
    w, sent = _wiring(began_at=lambda payload: 98.6)          # 1.4 s old: it crossed once
    w.repeat = lambda key, payload: repeated.append((key, payload))
    servers, calls = _server(w)
    servers.serve(CALL, REQUEST + b"\x00")
    calls[-1].cb(calls[-1])
    assert sent == [(CALL, RESPONSE)] and repeated == []


def copier():
    """Fates whose `copy_again` records what it offers (as under turns: taken)."""
    clock = ManualClock()
    copied = []
    fates = Fates(clock, lambda k, p: False, lambda k, p, until: True,
                  lambda k, p, until, answer, published: copied.append((k, p, until)) or True)
    return fates, copied, clock


def test_a_request_awaiting_its_answer_told_lost_is_offered_again_at_once():
    fates, copied, _ = copier()
    fates.awaiting(CALL, REQUEST, 12.0, lambda: True, ANSWER)
    fates.told(CALL, REQUEST, False)
    assert copied == [(CALL, REQUEST, 12.0)] and fates.stats()["copied"] == 1
    assert not fates.lost(CALL, REQUEST)             # offered: no copy left due on a timer


def test_a_message_answered_past_its_deadline_or_told_arrived_is_not_offered_again():
    fates, copied, clock = copier()
    fates.awaiting(CALL, REQUEST, 12.0, lambda: False, ANSWER)    # answered meanwhile
    fates.told(CALL, REQUEST, False)
    other = bytes((2, CALL, 8, 1))
    fates.awaiting(CALL, other, 12.0, lambda: True, ANSWER)
    clock.advance(13.0)                                          # its deadline passed
    fates.told(CALL, other, False)
    third = bytes((2, CALL, 9, 1))
    fates.awaiting(CALL, third, 30.0, lambda: True, ANSWER)
    fates.told(CALL, third, True)                                # arrived: the peer has it
    fates.told(CALL, third, False)                               # an older copy's loss
    assert copied == []


def test_a_copy_not_taken_on_the_link_thread_is_left_to_the_timer():
    clock = ManualClock()
    fates = Fates(clock, lambda k, p: False, lambda k, p, until: True, lambda k, p, until, a, published: False)
    fates.awaiting(CALL, REQUEST, 12.0, lambda: True, ANSWER)
    fates.told(CALL, REQUEST, False)
    assert fates.lost(CALL, REQUEST) and fates.stats()["copied"] == 0


GOAL_ANSWER = bytes((3, CALL, 9, 1))                 # a goal's answer: accepted
RESULT = bytes((3, CALL, 9, 4, 0, 1))                # its result, which says accepted too


def test_a_result_stands_in_for_its_goals_answer_until_the_answer_is_told_arrived():
    clock = ManualClock(100.0)
    fates = Fates(clock, lambda k, p: False, lambda k, p, until: True)
    fates.answered_by(CALL, GOAL_ANSWER, RESULT, 106.0)
    assert fates.stands_in(CALL, RESULT) == 106.0
    fates.told(CALL, GOAL_ANSWER, True)              # the answer arrived after all
    assert fates.stands_in(CALL, RESULT) is None
    other = Fates(clock, lambda k, p: False, lambda k, p, until: True)
    other.answered_by(CALL, GOAL_ANSWER, RESULT, 106.0)
    clock.advance(6.0)                               # the answer's deadline passed
    assert other.stands_in(CALL, RESULT) is None
    other.answered_by(CALL, GOAL_ANSWER, RESULT)     # no deadline given: it need not
    assert other.stands_in(CALL, RESULT) is None


def _result_told_lost(answers_until: float, answer_arrived: bool = False,
                      waiting: bool = False) -> list:
    """A served goal's result, awaiting its acknowledgement for 2 accept timeouts, told
    lost under turns: what gets a copy in its turn (`repeat`). `waiting`: its copy due by
    the round already waits in the link."""
    w, sent = _wiring()
    repeated = []
    w.repeat = lambda key, payload: repeated.append((key, payload))
    w.turns = lambda: 3
    if waiting:
        w.waiting = lambda key, payload: True
        sent.append((CALL, RESULT))                  # offered before the report came
    if answer_arrived:
        w.fates.told(CALL, GOAL_ANSWER, True)
    w.fates.answered_by(CALL, GOAL_ANSWER, RESULT, answers_until)
    w.fates.awaiting(CALL, RESULT, 124.0, lambda: True, RESULT[:3])
    w.fates.told(CALL, RESULT, False)
    assert sent == [(CALL, RESULT)]                  # offered again at once either way
    return repeated


def test_a_lost_result_standing_in_for_its_goals_answer_is_copied_in_turn_in_the_answers_last_rounds():
    from uwgen.bridge.wiring import ANSWER_URGENT_ROUNDS
    # turn_gap 3 s: the answer's last ANSWER_URGENT_ROUNDS rounds are urgent
    assert _result_told_lost(100.0 + ANSWER_URGENT_ROUNDS * 3.0 - 0.5) == [(CALL, RESULT)]
    assert _result_told_lost(100.0 + ANSWER_URGENT_ROUNDS * 3.0 + 0.5) == []   # rounds left
    # the answer arrived: the result is only a result, 24 s from its own deadline
    assert _result_told_lost(100.0 + ANSWER_URGENT_ROUNDS * 3.0 - 0.5, answer_arrived=True) == []


def test_a_copy_already_waiting_in_the_link_when_told_lost_gets_its_copy_in_turn_when_urgent():
    from uwgen.bridge.wiring import ANSWER_URGENT_ROUNDS
    # its copy due by the round went into the link before the report told it lost: that copy
    # is the repair (not sent twice), and in the answer's last rounds it gets its echo
    assert _result_told_lost(100.0 + ANSWER_URGENT_ROUNDS * 3.0 - 0.5, waiting=True) == [(CALL, RESULT)]
    assert _result_told_lost(100.0 + ANSWER_URGENT_ROUNDS * 3.0 + 0.5, waiting=True) == []


def test_a_result_standing_in_for_its_goals_answer_waits_for_its_news_report_unless_urgent():
    state, w, clock = wired(turns=3)
    urgent = [False]
    w.urgent = lambda deadline, answer=False: urgent[0] and answer
    standing, late = Leg(turn=3), Leg(turn=3)
    state.turns = 5                                  # the turn that carried it, and one more
    assert not copy_due(w, CALL, RESULT, standing, 10.0, rto=3.0, deadline=20.0, answer=True)
    urgent[0] = True                                 # the answer's last rounds: no waiting
    assert copy_due(w, CALL, RESULT, late, 10.0, rto=3.0, deadline=20.0, answer=True)
    urgent[0] = False
    state.turns = 6                                  # NEWS_ROUNDS ended: nothing told still
    assert copy_due(w, CALL, RESULT, standing, 11.0, rto=3.0, deadline=20.0, answer=True)
