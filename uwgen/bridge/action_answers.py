"""What comes back over the link for this side's goals (wire format 13): answers, results and
feedback, and the timers that resend, ask or give up when they do not come. The half of
`uwgen.bridge.actions.ActionStandIns` that the link and the clock drive; the stand-ins'
rclpy callbacks are the other half. `GoalState` (one goal in flight) lives here, so the stand-ins
import it from this module and nothing here imports them back.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rclpy.task import Future

from uwgen.bridge.copies import copy_due
from uwgen.runtime.wire.codec import pack_items
from uwgen.runtime.wire.table import ABORTED, ACCEPTED, REJECTED, RESULTS

if TYPE_CHECKING:
    from uwgen.bridge.calls import CallTable
    from uwgen.bridge.counters import ActionCounters
    from uwgen.bridge.wiring import Wiring
    from uwgen.runtime.delivery.reliable import RttEstimator


@dataclass
class GoalState:
    """One local goal in flight over the link (client side)."""

    ident: int                                    # the action's id
    handle: int
    request: Any                                  # the goal message (the key rclpy gives back)
    answer: Future = field(default_factory=Future)   # -> ACCEPTED or REJECTED
    result: Future = field(default_factory=Future)   # -> (status, result message)
    cancel: Future | None = None                  # -> CANCELING or CANCEL_REFUSED
    cancel_deadline: float = 0.0
    goal_handle: Any = None                       # rclpy ServerGoalHandle, once accepted
    early_feedback: Any = None                    # feedback that came before the goal handle
    payload: bytes = b""                          # the goal as sent (sent again unchanged)
    sends: int = 1
    turn: int | None = None                       # own turns ended while it waited (copies.py)
    held: bool = False                            # timer: its first copy waited once more (copies.py)
    next_send: float = float("inf")               # when to send it again while unanswered (none
                                                  # until it is first sent: the expiry timer
                                                  # may run while the goal is being encoded)
    next_query: float = 0.0                       # accepted, no result: when to ask for it
    sent_at: float = 0.0                          # when the goal first left
    asking: bool = False                          # unanswered past accept_timeout: asking


class GoalAnswers:
    """Answers, results and feedback for this side's goals, and their timers. The stand-ins
    (`ActionStandIns`) set up what these read: the wiring, per action id its codec, counters,
    call table of handles, round-trip estimator and this side's handles, and the goals in
    flight by their request."""

    w: Wiring
    offered: dict[int, Any]
    counters: dict[int, ActionCounters]
    tables: dict[int, CallTable]
    rtt: dict[int, RttEstimator]
    handles: dict[int, range]
    _states: dict[int, GoalState]

    # -- the link (executor thread) --------------------------------------------------------

    # -- the link (executor thread) --------------------------------------------------------

    def on_response(self, ident: int, payload: bytes) -> None:
        codec, counters, table = self.offered[ident], self.counters[ident], self.tables[ident]
        try:
            handle, code, result = codec.decode_response(payload)
        except ValueError as exc:
            counters.decode_errors += 1
            self.w.say_once(f"dact{ident}", f"{codec.name}: response dropped, does not decode: {exc}")
            return
        if handle not in self.handles[ident]:
            counters.other_sides += 1       # an answer or result for another client side
            return
        if code in RESULTS:
            pending = table.complete(ident, handle)
            # Acknowledged, a copy whatever became of it (our last ack was lost). Where the
            # link's reports tell the server side that a result arrived (fates.py), the
            # report acknowledges the first: a copy comes only when the report was lost.
            if pending is None or not self.w.reports:
                if self.w.send(ident, codec.encode_result_status(handle, received=True)):
                    counters.result_acks += 1
            if pending is None:
                self._no_goal(ident, handle)
                return
            state = pending.token
            if not state.answer.done():   # the answer was lost; the result says it all
                if state.sends > 1:
                    self.w.withdraw(ident, state.payload)
                counters.accepted += 1
                state.answer.set_result(ACCEPTED)
            state.result.set_result((code, result))
            return
        pending = table.get(ident, handle)
        state = pending.token if pending is not None else None
        if state is None:
            self._no_goal(ident, handle)
            if code == ACCEPTED:     # a goal given up here (accept timeout) runs there: stop it
                self.w.send(ident, codec.encode_cancel(handle))
        elif code in (ACCEPTED, REJECTED) and not state.answer.done():
            if state.sends > 1:
                self.w.withdraw(ident, state.payload)     # a copy not yet left: no air time
            if state.sends == 1 and not state.asking:   # Karn: only an unambiguous round trip
                self.rtt[ident].sample(self.w.clock.now() - state.sent_at)
            if code == ACCEPTED:
                counters.accepted += 1
                if state.asking:
                    self.w.log.info(f"{codec.name}: goal {state.handle} runs on the server side "
                                    "(its answer came late): accepted")
                pending.deadline = state.sent_at + codec.result_timeout if state.asking else \
                    self.w.clock.now() + codec.result_timeout
                state.next_query = self.w.clock.now() + codec.accept_timeout
            else:
                counters.rejected += 1
                table.complete(ident, handle)
            state.answer.set_result(code)
        elif code not in (ACCEPTED, REJECTED) and state.cancel is not None and not state.cancel.done():
            state.cancel.set_result(code)
        elif code == ACCEPTED and state.answer.done() and state.next_query:
            pass                      # the goal still runs: the reply to our result request
        elif code == REJECTED and state.answer.done() and not state.result.done():
            # the reply to our result request: no such goal there (its bridge restarted
            # and did not find it running): it will not finish
            counters.goals_lost_there += 1
            self.w.throttle.report(f"alostthere{ident}", f"{codec.name}: goal {handle} is no "
                                   "longer known on the server side (its bridge restarted?): "
                                   "aborted here", expected=True)
            table.complete(ident, handle)
            state.result.set_result((ABORTED, codec.ros_class().Result()))
        else:
            counters.late_answers += 1     # a repeated answer: a copy crossed on the link

    def _no_goal(self, ident: int, handle: int) -> None:
        """An answer or result for no goal in flight: a late copy when the handle's goal has
        finished lately here (answers and results are re-sent until acknowledged, so copies
        cross on a lossy link: counted, not a drop), else unknown (a drop, warned)."""
        if self.tables[ident].finished(ident, handle) is not None:
            self.counters[ident].late_answers += 1
        else:
            self.counters[ident].unknown += 1

    def on_feedback(self, ident: int, payload: bytes) -> None:
        codec, counters = self.offered[ident], self.counters[ident]
        try:
            handle, feedback = codec.decode_feedback(payload)
        except ValueError as exc:
            counters.decode_errors += 1
            self.w.say_once(f"dfb{ident}", f"{codec.name}: feedback dropped, does not decode: {exc}")
            return
        if handle not in self.handles[ident]:
            counters.other_sides += 1
            return
        pending = self.tables[ident].get(ident, handle)
        if pending is None:
            counters.late_feedback += 1   # latest-only feedback may trail its goal's result
            return
        state = pending.token
        if state.goal_handle is None:
            state.early_feedback = feedback
            return
        try:
            state.goal_handle.publish_feedback(feedback)
        except Exception as exc:   # a codec/rclpy class mismatch: counted, never raised
            counters.decode_errors += 1
            self.w.say_once(f"pfb{ident}", f"{codec.name}: cannot publish feedback: {exc!r}")
            return
        counters.feedback += 1

    # -- timers ----------------------------------------------------------------------------

    def expire(self) -> None:
        now, say = self.w.clock.now(), self.w.throttle.report   # a dead link times out many
        for ident, table in self.tables.items():
            codec, counters = self.offered[ident], self.counters[ident]
            for pending in table.pending(ident):
                state = pending.token
                if not state.answer.done() and not state.asking and pending.deadline <= now:
                    # No answer within accept_timeout: the goal may run there all the same
                    # (its answers lost). Ask, until result_timeout from the call.
                    state.asking = True
                    state.next_query = now
                    pending.deadline = state.sent_at + max(codec.result_timeout, codec.accept_timeout)
                    counters.accept_timeouts += 1
                    say(f"aaccept{ident}", f"{codec.name}: goal {state.handle} got no answer "
                                           f"within {codec.accept_timeout:g} s: asking the server "
                                           "side whether it runs (not rejected while it may)",
                        expected=True)
            for pending in table.expire():
                state = pending.token
                if not state.answer.done():
                    counters.unknown_outcomes += 1
                    say(f"aunknown{ident}", f"{codec.name}: goal {state.handle}: no word from the "
                                            f"server side within {codec.result_timeout:g} s: "
                                            "rejected here, a cancel is sent; it may have run "
                                            "there (counted unknown_outcomes)", expected=True)
                    self.w.send(ident, codec.encode_cancel(state.handle))
                    state.answer.set_result(REJECTED)
                    continue
                counters.result_timeouts += 1
                say(f"aresult{ident}", f"{codec.name}: goal {state.handle} got no result within "
                                       f"{codec.result_timeout:g} s: aborted (a cancel is sent)", expected=True)
                self.w.send(ident, codec.encode_cancel(state.handle))
                state.result.set_result((ABORTED, codec.ros_class().Result()))
            for pending in table.pending(ident):
                state = pending.token
                if (state.answer.done() or state.asking) and not state.result.done() \
                        and state.next_query <= now:
                    # No result yet, or no answer: ask (the server side re-sends the result,
                    # says the goal still runs, or answers 0 when it knows no such goal).
                    state.next_query = now + (self.rtt[ident].rto if state.asking
                                              else codec.accept_timeout)
                    counters.result_queries += 1
                    self.w.send(ident, codec.encode_result_status(state.handle, received=False))
                if not state.answer.done() and not state.asking and state.payload \
                        and copy_due(self.w, ident, state.payload, state, now, self.rtt[ident].rto,
                                     state.sent_at + codec.accept_timeout):
                    rtt = self.rtt[ident]
                    rtt.backoff()
                    state.sends += 1
                    state.next_send = now + rtt.rto
                    counters.goal_resends += 1
                    # its answer or result takes it back; its age item is the goal's
                    if self.w.send(ident, state.payload, published=state.sent_at):
                        self.w.expect(pack_items([3, ident, state.handle]), ident, state.payload,
                                      echo=self.w.urgent(state.sent_at + codec.accept_timeout))
        for state in list(self._states.values()):
            if state.cancel is not None and not state.cancel.done() and state.cancel_deadline <= now:
                codec = self.offered[state.ident]
                self.counters[codec.id].cancel_timeouts += 1
                say(f"acancel{codec.id}", f"{codec.name}: cancel of goal {state.handle} got no "
                                          "answer: refused")
                state.cancel.set_result(None)
