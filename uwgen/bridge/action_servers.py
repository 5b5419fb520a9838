"""Actions served here: goals from the link are sent to the real action server through an
rclpy ActionClient, and its answers, feedback and result go back (wire format 13).

Per goal handle of the client side: `[2, id, handle, goal...]` becomes `send_goal_async`;
its acceptance is answered `[3, id, handle, 1]` (or 0: rejected, also when no local
server appears within half the accept_timeout: a goal that arrives before the local
server is discovered waits for it); the result is requested locally at once and pushed as
`[3, id, handle, status, result...]`; feedback goes out as `[0, id, handle, feedback...]`
on the action's latest-only feedback channel. `[2, id, handle]` cancels the goal and is
answered 3 (canceling) or 2 (refused).

Losses: a goal that comes again (the client side sends it again while unanswered) is
answered again if it was accepted, and a goal that finished lately gets its result again
(`uwgen.bridge.action_results`, which also sends results again until acknowledged; after a
restart, from the local server's goal list: `uwgen.bridge.orphans`), so a lost answer or
result costs a repeat, not a second run. A local server that does not
answer within `accept_timeout` is answered 0; a goal that does not finish within
`result_timeout` is cancelled and reported aborted; a local server that disappears during
goals gets them reported aborted after SERVER_GONE_GRACE.
"""
from __future__ import annotations

import random
from typing import Any

from rclpy.action import ActionClient
from rclpy.task import Future

from uwgen.bridge.action_results import ResultBook, Served, could_copy
from uwgen.bridge.adoption import GoalAdoption
from uwgen.bridge.copies import copy_due
from uwgen.bridge.counters import ActionCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.orphans import OrphanWatch, goal_uuid
from uwgen.bridge.plan import FEEDBACK_KEY_BASE
from uwgen.bridge.wiring import Wiring
from uwgen.runtime.wire.codec import KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC
from uwgen.runtime.delivery.reliable import command_rtt
from uwgen.runtime.wire.table import (ABORTED, ACCEPTED, CANCEL_REFUSED, CANCELING, REJECTED, RESULTS)

SERVER_GONE_GRACE = 1.0   # seconds the local server may be missing before its goals abort


class ActionServers(GoalAdoption):
    def __init__(self, wiring: Wiring, codecs: list[Any], counters: dict[int, ActionCounters]):
        self.w = wiring
        self.codecs = codecs
        self.counters = counters
        self.served: dict[int, tuple[Any, Any]] = {}       # id -> (codec, ActionClient)
        self.goals: dict[int, dict[int, Served]] = {}      # id -> handle -> goal
        self._gone_since: dict[int, float] = {}
        self.results: dict[int, ResultBook] = {}           # id -> results kept and re-sent
        self.own_uuids: set[bytes] = set()                 # goals this start sent
        self.watches: dict[int, OrphanWatch] = {}          # id -> its status topic reader
        self._rng = random.SystemRandom()
        self._deferred: set[tuple[int, int]] = set()       # result requests answered later
        # goals whose wait for a local server ended before its goal list was known: answered
        # once it is (id, handle) -> (payload, arrived); never sent to the server
        self._unlisted: dict[tuple[int, int], tuple[bytes, float]] = {}
        for codec in codecs:
            counters[codec.id] = ActionCounters()
            cls = wiring.ros_class(codec, "action")
            if cls is None:
                continue
            client = ActionClient(wiring.node, cls, codec.name, callback_group=wiring.main_group)
            self.served[codec.id] = (codec, client)
            wiring.loops.watch_server(codec.name, action=True)
            self.goals[codec.id] = {}
            self.results[codec.id] = ResultBook(
                codec.accept_timeout, command_rtt(codec.accept_timeout, wiring.options.link.period,
                                                  wiring.round_trip, wiring.turn_gap))
            self.watches[codec.id] = OrphanWatch(
                wiring.node, codec.name, codec.id,
                lambda handle, uuid, info, i=codec.id: self._adopt(i, handle, uuid, info),
                self.own_uuids, wiring.clock.now(), callback_group=wiring.main_group)

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in self.served:
            dispatcher.route(KIND_REQUEST, ident, self.on_request)
            dispatcher.sends(KIND_RESPONSE, ident)
            dispatcher.sends(KIND_TOPIC, ident)

    def _offer(self, ident: int, payload: bytes, what: str, key: int | None = None,
               again: bool = False) -> bool:
        # an answer or result equal to one still waiting in the link is not queued twice;
        # `again`: the client side asked for it again (the link copies it in its turn)
        if self.w.offer_once(ident if key is None else key, payload, again):
            return True
        self.counters[ident].reply_refused += 1
        self.w.say_once(f"aref{ident}{what}", f"{self.served[ident][0].name}: {what} refused by the link")
        return False

    def _answer(self, ident: int, handle: int, code: int) -> None:
        codec = self.served[ident][0]
        answer = codec.encode_answer(handle, code)
        began = self._began(self.goals[ident].get(handle))
        # a goal that came late (its first copies lost), or whose answer was lost and asked
        # for again, with too few rounds left: its answer gets its copy in its turn
        if self._offer(ident, answer, "answer",
                       again=self.w.answer_urgent(began, codec.accept_timeout)):
            self.counters[ident].answers += 1
            # a lost answer goes again at once, within the goal's time (fates.py)
            self.w.fates.repairable(ident, answer, self.w.callers_deadline(began, codec.accept_timeout))

    def _began(self, entry: Served | None) -> float:
        """When the goal of `entry` (None: not kept) began on the client side (Wiring.began)."""
        if entry is not None and entry.began is not None:
            return entry.began
        return self.w.began(b"", entry.arrived if entry is not None else self.w.clock.now())

    def _result(self, ident: int, handle: int, status: int, result: Any, entry: Served) -> None:
        codec = self.served[ident][0]
        try:
            payload = codec.encode_result(handle, status, result)
        except ValueError as exc:
            self.counters[ident].encode_errors += 1
            self.w.throttle.report(f"aenc{ident}", f"{codec.name}: result of goal {handle} cannot "
                                                   f"be encoded ({exc}); reported aborted")
            payload = codec.encode_result(handle, ABORTED, codec.ros_class().Result())
        self.w.fates.forget(ident, payload)       # its bytes may repeat an old result's
        # the result is the goal's answer too: a lost answer is not repaired, and until the
        # answer is told arrived the result stands in for it, on its deadline (fates.py)
        self.w.fates.answered_by(ident, codec.encode_answer(handle, ACCEPTED), payload,
                                 self.w.callers_deadline(self._began(entry), codec.accept_timeout))
        if self._offer(ident, payload, "result", again=self.w.urgent_copy(ident, payload, None)):
            self.counters[ident].results_sent += 1
        book = self.results[ident]
        book.sent(handle, entry.payload, payload, entry.arrived, self.w.clock.now(), self.w.turns())
        unacked = book.unacked[handle]
        self.w.fates.awaiting(ident, payload, unacked.until,
                              lambda: book.unacked.get(handle) is unacked,
                              codec.encode_result_status(handle, received=True))

    # -- the link (executor thread) --------------------------------------------------------

    def on_request(self, ident: int, payload: bytes) -> None:
        codec, client = self.served[ident]
        counters, goals = self.counters[ident], self.goals[ident]
        try:
            status = codec.decode_result_status(payload)
            if status is not None:
                self._result_status(ident, *status)
                return
            handle, goal = codec.decode_request(payload)
        except ValueError as exc:
            counters.decode_errors += 1
            self.w.say_once(f"dreq{ident}", f"{codec.name}: request dropped, does not decode: {exc}")
            return
        if goal is None:
            self._cancel(ident, handle)
            return
        counters.goal_requests += 1
        if self.w.loops.blocked(codec.name):
            counters.loop_guard += 1      # our goal would reach another bridge's stand-in
            return
        now = self.w.clock.now()
        # may it copy a goal a previous start of this bridge took? (orphans.py)
        unsure = self.w.may_predate(payload, self.watches[ident].started)
        if self._repeat(ident, handle, payload, could_copy(unsure), now):   # in flight, or done
            counters.duplicate_goals += 1
            return
        self.results[ident].forget(handle)        # a new goal on a handle used before
        self.watches[ident].forget(handle)
        # A goal waits for the local server, and one that may copy a goal a previous start
        # took for its goal list too (orphans.py: a copy of a goal left running is not run
        # again), at most half its accept_timeout: the client side's clock started before
        # the goal's trip, and the answer needs one too.
        entry = goals[handle] = Served(None, now + codec.accept_timeout / 2, payload=payload,
                                       arrived=now, goal=goal, began=self.w.began(payload, now),
                                       unsure=unsure)
        if self._may_send(ident, entry, now):
            self._send_goal(ident, handle, entry)
        else:
            counters.waited += 1     # sent once the server (and its list) are known (_send_waiting)

    def _may_send(self, ident: int, entry: Served, now: float) -> bool:
        """Whether a goal that came may go to the local server (orphans.py): it is ready, and
        the goal began after this start, or may copy a goal a previous start took and the
        server's goal list is known; on a link that cannot tell (no age item), the list is
        known or taken as known (`OrphanWatch.listed`), or the goal's wait is over."""
        if not self.served[ident][1].server_is_ready():
            return False
        watch = self.watches[ident]
        if entry.unsure is None:
            return watch.listed(now) or entry.deadline <= now
        return not entry.may_copy or watch.heard_or_grace(now)

    def _send_goal(self, ident: int, handle: int, entry: Served) -> None:
        from unique_identifier_msgs.msg import UUID
        client = self.served[ident][1]
        uuid = goal_uuid(ident, handle, self._rng, entry.payload,            # orphans.py
                         self.w.wall_at(entry.arrived))
        self.own_uuids.add(uuid)
        entry.sent = client.send_goal_async(
            entry.goal, feedback_callback=lambda fb: self._feedback(ident, handle, fb),
            goal_uuid=UUID(uuid=list(uuid)))
        entry.deadline = self.w.clock.now() + self.served[ident][0].accept_timeout
        entry.goal = None
        entry.sent.add_done_callback(lambda f: self._answered(ident, handle, f))

    def _send_waiting(self, ident: int, now: float) -> None:
        """Send the goals that waited for the local server, now that it is ready, and for
        one that may copy a goal a previous start took, its goal list is known (orphans.py:
        never on a guess; one whose wait ends before leaves it unlisted, answered once the
        list is known, `expire`)."""
        for handle, entry in list(self.goals[ident].items()):
            if entry.sent is None and self._may_send(ident, entry, now):
                if not (entry.may_copy
                        and self._copy_of_finished(ident, handle, entry.payload, entry.arrived)):
                    self._send_goal(ident, handle, entry)

    def _result_status(self, ident: int, handle: int, received: bool) -> None:
        """The client side has the result of goal `handle` (stop sending it), or wants it."""
        counters = self.counters[ident]
        if received:
            acked = self.results[ident].acknowledged(handle, self.w.clock.now())
            if acked is not None:
                counters.results_acked += 1
                if acked.sends > 1:
                    self.w.withdraw(ident, acked.payload)   # a copy not yet left
            return
        counters.result_queries += 1
        entry = self.goals[ident].get(handle)
        if entry is not None:
            if entry.goal_handle is not None:
                self._answer(ident, handle, ACCEPTED)     # still running (asked: no hurry)
            return
        recent = self.results[ident].result_of(handle)
        if recent is not None:
            counters.results_resent += 1
            self._offer(ident, recent, "result")
            return
        finished = self.watches[ident].finished_goal(handle)
        if finished is not None:                  # it finished while no bridge watched it
            self._adopt(ident, handle, *finished, done=True)
            return
        # Neither running nor finished here: never arrived (a goal older than its
        # accept_timeout is refused on arrival, so it never will), or this bridge restarted
        # and did not find it. Answered 0: no such goal here; not before the local server's
        # goal list was read (a goal about to be adopted is not "lost").
        if not self.watches[ident].heard_or_grace(self.w.clock.now()):
            self._deferred.add((ident, handle))           # answered once it knows (expire)
            return
        codec = self.served[ident][0]
        self.w.throttle.report(f"alost{ident}", f"{codec.name}: the client side asks about "
                                                f"goal {handle}, unknown here: answered 'no such "
                                                "goal'", expected=True)
        self._answer(ident, handle, REJECTED)
        counters.lost_goals += 1

    def _resend_results(self, ident: int, now: float) -> None:
        """Results not acknowledged go again when a copy is due (copies.py), until the book
        gives them up."""
        counters, book = self.counters[ident], self.results[ident]
        for handle, unacked in list(book.unacked.items()):
            if self.w.fates.arrived(ident, unacked.payload):     # told by the link (fates.py)
                book.acknowledged(handle, now)
                counters.results_told_arrived += 1
        fates = self.w.fates
        for payload in book.due(now, lambda u: copy_due(
                self.w, ident, u.payload, u, now, book.rtt.rto,
                deadline=fates.stands_in(ident, u.payload), answer=True)):
            if payload is None:
                counters.results_unacked += 1
                continue
            counters.results_resent += 1
            if self._offer(ident, payload, "result"):     # its acknowledgement takes it back
                codec = self.served[ident][0]
                handle = codec.decode_response(payload, ros=False)[0]
                # a copy in its turn only when urgent as its goal's answer: a result alone
                # has result_timeout, many rounds (echoes.py)
                self.w.expect(codec.encode_result_status(handle, received=True), ident, payload,
                              echo=self.w.urgent_copy(ident, payload, None))

    def _repeat(self, ident: int, handle: int, payload: bytes, may_copy: bool, now: float) -> bool:
        """Answer a goal that came again at `now`; True when it was one (then it is not run).
        `may_copy`: it may copy a goal a previous start took (orphans.py)."""
        unlisted = self._unlisted.get((ident, handle))
        if unlisted is not None and unlisted[0] == payload:
            return True                  # held past its budget: answered once the list is known
        entry = self.goals[ident].get(handle)
        if entry is not None:
            if entry.goal_handle is not None and entry.payload == payload:
                self.counters[ident].repeated_replies += 1
                self._answer(ident, handle, ACCEPTED)          # the first answer was lost
            return True                                    # else: the answer is still to come
        result = self.results[ident].repeat_of(handle, payload, now)
        if result is None:
            return may_copy and self._copy_of_finished(ident, handle, payload, now)
        self.counters[ident].repeated_replies += 1
        arrived = self.results[ident].recent[handle].arrived   # the answer and result were lost
        self._offer(ident, result, "result", again=self.w.answer_urgent(
            self.w.began(payload, arrived), self.served[ident][0].accept_timeout))
        return True

    def _answered(self, ident: int, handle: int, sent: Future) -> None:
        codec = self.served[ident][0]
        entry = self.goals[ident].get(handle)
        exc = sent.exception() if not sent.cancelled() else None
        goal_handle = sent.result() if exc is None and not sent.cancelled() else None
        if entry is None or entry.sent is not sent:   # gave up on it already
            if goal_handle is not None and goal_handle.accepted:
                goal_handle.cancel_goal_async()       # nobody waits for it any more
            return
        if goal_handle is None or not goal_handle.accepted:
            if exc is not None:
                self.counters[ident].server_errors += 1
                self.w.throttle.report(f"aerr{ident}", f"{codec.name}: goal {handle} failed "
                                                       f"locally: {exc}")
            del self.goals[ident][handle]
            self._answer(ident, handle, REJECTED)
            return
        entry.goal_handle = goal_handle
        entry.deadline = self.w.clock.now() + codec.result_timeout
        self._answer(ident, handle, ACCEPTED)
        goal_handle.get_result_async().add_done_callback(
            lambda f: self._finished(ident, handle, goal_handle, f))
        if entry.cancel_wanted:
            self._cancel(ident, handle)

    def _finished(self, ident: int, handle: int, goal_handle: Any, done: Future) -> None:
        entry = self.goals[ident].get(handle)
        if entry is None or entry.goal_handle is not goal_handle:
            return                     # already reported (timeout, server gone)
        del self.goals[ident][handle]
        if done.cancelled() or done.exception() is not None:
            self.counters[ident].server_errors += 1
            self._result(ident, handle, ABORTED, self.served[ident][0].ros_class().Result(), entry)
            return
        response = done.result()
        status = response.status if response.status in RESULTS else ABORTED
        self._result(ident, handle, status, response.result, entry)

    def _feedback(self, ident: int, handle: int, message: Any) -> None:
        codec = self.served[ident][0]
        if codec.feedback_policy is None or handle not in self.goals[ident]:
            return
        try:
            payload = codec.encode_feedback(handle, message.feedback)
        except ValueError as exc:
            self.counters[ident].encode_errors += 1
            self.w.say_once(f"efb{ident}", f"{codec.name}: feedback not sent, cannot encode: {exc}")
            return
        if self._offer(ident, payload, "feedback", FEEDBACK_KEY_BASE + ident):
            self.counters[ident].feedback_sent += 1

    def _cancel(self, ident: int, handle: int) -> None:
        entry = self.goals[ident].get(handle)
        if entry is None:
            # Finished: its result is on its way, or the client side has given up on it.
            self.results[ident].stop_sending(handle)
            self._answer(ident, handle, CANCEL_REFUSED)
            return
        if entry.sent is None:                             # still waiting for the local server
            del self.goals[ident][handle]
            self._answer(ident, handle, REJECTED)
            return
        if entry.goal_handle is None:
            entry.cancel_wanted = True                     # answered once the server has answered
            return
        entry.cancel_wanted = False
        entry.goal_handle.cancel_goal_async().add_done_callback(
            lambda f: self._cancel_answered(ident, handle, f))

    def _cancel_answered(self, ident: int, handle: int, done: Future) -> None:
        ok = not done.cancelled() and done.exception() is None and bool(done.result().goals_canceling)
        self._answer(ident, handle, CANCELING if ok else CANCEL_REFUSED)

    # -- timers ----------------------------------------------------------------------------

    def expire(self) -> None:
        now, say = self.w.clock.now(), self.w.throttle.report
        for ident, handle in list(self._deferred):
            if self.watches[ident].heard_or_grace(now):
                self._deferred.discard((ident, handle))
                if handle not in self.goals[ident]:
                    self.counters[ident].result_queries -= 1   # counted when it came
                    self._result_status(ident, handle, False)
        for (ident, handle), (payload, arrived) in list(self._unlisted.items()):
            if self.watches[ident].heard_or_grace(now):
                del self._unlisted[(ident, handle)]
                self._answer_unlisted(ident, handle, payload, arrived)
        for ident, goals in self.goals.items():
            codec, client = self.served[ident]
            counters = self.counters[ident]
            self._send_waiting(ident, now)
            self._resend_results(ident, now)
            for handle, entry in list(goals.items()):
                if entry.deadline > now:
                    continue
                del goals[handle]
                if entry.sent is None:
                    counters.no_server += 1
                    if entry.may_copy and not self.watches[ident].heard_or_grace(now):
                        # The goal list is not known: this may be the copy of a goal a
                        # previous start left running on a server not seen yet (orphans.py),
                        # and "rejected" would then lie. Not run; answered once it is known.
                        self._unlisted[(ident, handle)] = (entry.payload, entry.arrived)
                        continue
                    self._reject_unserved(ident, handle)
                    continue
                counters.server_timeouts += 1
                if entry.goal_handle is None:
                    say(f"aanswer{ident}", f"{codec.name}: local server did not answer goal "
                                           f"{handle} within {codec.accept_timeout:g} s: rejected")
                    self._answer(ident, handle, REJECTED)
                else:
                    say(f"aresult{ident}", f"{codec.name}: goal {handle} did not finish within "
                                           f"{codec.result_timeout:g} s: cancelled, reported aborted")
                    entry.goal_handle.cancel_goal_async()
                    self._result(ident, handle, ABORTED, codec.ros_class().Result(), entry)
            self._check_server(ident, now)

    def _reject_unserved(self, ident: int, handle: int, listless: bool = False) -> None:
        """Goal `handle` waited for a local server that did not appear, or (`listless`) it
        may copy a goal a previous start took and waited past its budget for the server's
        goal list, which shows no such goal: rejected (it never ran), said."""
        codec = self.served[ident][0]
        budget = codec.accept_timeout / 2
        why = (f"it may have copied a goal of a previous start of this bridge, and the local "
               f"server's goal list, which shows none, was not known within {budget:g} s"
               if listless else f"no local action server appeared within {budget:g} s")
        self.w.throttle.report(f"anoserver{ident}", f"{codec.name}: goal {handle} rejected: {why}")
        self._answer(ident, handle, REJECTED)

    def _check_server(self, ident: int, now: float) -> None:
        """Abort the goals of a local server that has disappeared (for SERVER_GONE_GRACE)."""
        codec, client = self.served[ident]
        goals = {h: e for h, e in self.goals[ident].items() if e.sent is not None}
        if not goals or client.server_is_ready():
            self._gone_since.pop(ident, None)
            return
        since = self._gone_since.setdefault(ident, now)
        if now - since < SERVER_GONE_GRACE:
            return
        self.w.log.error(f"{codec.name}: the local action server is gone: {len(goals)} goal(s) "
                         "reported aborted")
        for handle, entry in goals.items():
            del self.goals[ident][handle]
            self.counters[ident].server_gone += 1
            self._result(ident, handle, ABORTED, codec.ros_class().Result(), entry)
        self._gone_since.pop(ident, None)
