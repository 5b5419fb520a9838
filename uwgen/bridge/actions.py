"""Actions offered here, served on another side: a real rclpy ActionServer stands in for the
remote one and carries each goal over the link (wire format 13).

A local client's goal takes a one-byte handle (from a CallTable per action: this side's
share of the handles 0..23, see manifest.model.handle_range; at most `max_goals` in
flight) and goes out as `[2, id, handle, goal...]`; the goal callback waits for the
answer and accepts or rejects the local goal with it. The result is
pushed by the server side (`[3, id, handle, status, result...]`) and completes the local
goal with the same terminal status; feedback (`[0, id, handle, feedback...]`) is
published to the local client. The status topic is the local ActionServer's own. A cancel
from the local client goes out as `[2, id, handle]` and its answer decides the local
cancel response.

Results: each result that arrives is acknowledged (`[2, id, 24 + handle, 0]`), also a
copy (the server side re-sends a result until acknowledged); an accepted goal with no
result asks for it (`[2, id, 24 + handle, 1]`) every accept_timeout.

Losses: a goal with no answer is sent again (same handle and bytes) when a copy is due
(uwgen.bridge.copies: once a round under the turns MAC, else every retransmission timeout,
reliable.command_rtt: measured from this action's goal/answer round trips, at most a
quarter of `accept_timeout`). A goal with no answer within `accept_timeout` may be
running there (only the answers lost), so it is never rejected then: the client side asks
the server side about it (a result request) until `result_timeout` from the call, and
accepts it when the server side says it runs or sends its result, or rejects it when the
server side knows no such goal (a goal is refused there once older than its accept_timeout,
so one unknown then never runs). With no word at all by `result_timeout` it is rejected
locally and a cancel is sent (counted `unknown_outcomes`: the one case where it may have
run). A cancel with no answer is refused locally; no result within `result_timeout` aborts
the goal locally and sends a cancel for it; an accepted goal the server side no longer
knows (its bridge restarted without finding it) is aborted (`goals_lost_there`). Every such
case is logged and counted in ~/status under `actions`.
"""
from __future__ import annotations

import random
from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future

from uwgen.bridge.action_answers import GoalAnswers, GoalState
from uwgen.bridge.calls import CallTable, CallTableFull
from uwgen.bridge.counters import ActionCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.wiring import Wiring
from uwgen.manifest.model import ACTION_HANDLES
from uwgen.runtime.wire.codec import KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC, pack_items
from uwgen.runtime.delivery.reliable import RttEstimator, command_rtt
from uwgen.runtime.wire.table import ACCEPTED, CANCELED, CANCELING, SUCCEEDED


class ActionStandIns(GoalAnswers):
    """The local ActionServers that stand in for the remote ones: their rclpy callbacks carry
    each goal and cancel over the link (what comes back: action_answers.GoalAnswers)."""

    def __init__(self, wiring: Wiring, codecs: list[Any], counters: dict[int, ActionCounters],
                 rng: random.Random | None = None, handles: dict[int, tuple[int, int]] | None = None):
        self.w = wiring
        self.codecs = codecs
        self.counters = counters
        self.offered: dict[int, Any] = {}            # id -> codec
        self.tables: dict[int, CallTable] = {}       # id -> goal handles in flight
        self.rtt: dict[int, RttEstimator] = {}       # id -> goal round trip (goal to answer)
        self.handles: dict[int, range] = {}          # id -> this side's handles
        self.servers: dict[int, Any] = {}    # id -> the stand-in ActionServer (absent: withdrawn)
        self._states: dict[int, GoalState] = {}      # id(goal message) -> its goal
        for codec in codecs:
            counters[codec.id] = ActionCounters()
            cls = wiring.ros_class(codec, "action")
            if cls is None:
                continue
            first, last = (handles or {}).get(codec.id, (0, ACTION_HANDLES - 1))
            # A handle rests 2 accept_timeouts before reuse: the server side answers a goal
            # that comes again on a handle from what it kept (action_servers.REPEAT_WINDOW).
            table = CallTable(wiring.clock, rng=rng, max_outstanding=codec.max_goals,
                              reuse_after=2 * codec.accept_timeout)
            table.set_seq_range(codec.id, first, last)
            self.handles[codec.id] = range(first, last + 1)
            self.tables[codec.id] = table
            self.rtt[codec.id] = command_rtt(codec.accept_timeout, wiring.options.link.period,
                                             wiring.round_trip, wiring.turn_gap)
            self.offered[codec.id] = codec
            self._offer(codec, cls)
            wiring.loops.watch_standin(codec.name, action=True,
                                       on_change=lambda blocked, c=codec, k=cls: self._loop(c, k, blocked))

    def _offer(self, codec: Any, cls: Any) -> None:
        self.servers[codec.id] = ActionServer(
            self.w.node, cls, codec.name, self._executor(codec),
            goal_callback=self._goal_callback(codec), cancel_callback=self._cancel_callback(codec),
            handle_accepted_callback=self._accepted, callback_group=self.w.service_group)

    def _loop(self, codec: Any, cls: Any, blocked: bool) -> None:
        """Withdraw the stand-in while another bridge here serves it (loops.py), and back."""
        if blocked and codec.id in self.servers:
            self.servers.pop(codec.id).destroy()
        elif not blocked and codec.id not in self.servers:
            self._offer(codec, cls)

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in self.offered:
            dispatcher.route(KIND_RESPONSE, ident, self.on_response)
            dispatcher.route(KIND_TOPIC, ident, self.on_feedback)
            dispatcher.sends(KIND_REQUEST, ident)

    # -- the local action server's callbacks (executor thread) -----------------------------

    def _goal_callback(self, codec: Any):
        counters, table, log = self.counters[codec.id], self.tables[codec.id], self.w.log

        async def on_goal(goal: Any) -> GoalResponse:
            counters.goals += 1
            if self.w.loops.blocked(codec.name):
                counters.loop_guard += 1
                # Never answered by the stand-in: the real server in this graph answers it.
                return await Future()
            try:
                pending = table.begin(codec.id, codec.accept_timeout)
            except CallTableFull:
                counters.refused += 1
                log.error(f"{codec.name}: goal rejected: {codec.max_goals} goals already in flight "
                          "(manifest max_goals)")
                return GoalResponse.REJECT
            state = pending.token = GoalState(codec.id, pending.seq, goal)
            try:
                payload = codec.encode_goal(state.handle, goal)
            except ValueError as exc:
                table.abandon(codec.id, state.handle)
                counters.refused += 1
                log.error(f"{codec.name}: goal rejected, cannot be encoded: {exc}")
                return GoalResponse.REJECT
            self.w.fates.forget(codec.id, payload)       # its bytes may repeat an old goal's
            if not self.w.send(codec.id, payload):
                table.abandon(codec.id, state.handle)
                counters.refused += 1
                log.error(f"{codec.name}: goal rejected: the link refused it (see ~/status)")
                return GoalResponse.REJECT
            state.turn = self.w.turns()
            state.payload = payload
            state.sent_at = self.w.clock.now()
            state.next_send = state.sent_at + self.rtt[codec.id].rto
            self.w.fates.awaiting(codec.id, payload, state.sent_at + codec.accept_timeout,
                                  lambda: not state.answer.done() and not state.asking,
                                  pack_items([3, codec.id, state.handle]), state.sent_at)
            if await state.answer != ACCEPTED:
                return GoalResponse.REJECT
            self._states[id(goal)] = state
            return GoalResponse.ACCEPT
        return on_goal

    def _accepted(self, goal_handle: Any) -> None:
        state = self._states.get(id(goal_handle.request))
        if state is not None:
            state.goal_handle = goal_handle
            if state.early_feedback is not None:
                try:
                    goal_handle.publish_feedback(state.early_feedback)
                except Exception:   # as in on_feedback: never raised (counted there)
                    self.counters[state.ident].decode_errors += 1
        goal_handle.execute()

    def _executor(self, codec: Any):
        counters = self.counters[codec.id]

        async def execute(goal_handle: Any) -> Any:
            state = self._states.get(id(goal_handle.request))
            if state is None:   # cannot happen: accepted goals have a state
                goal_handle.abort()
                return codec.ros_class().Result()
            try:
                status, result = await state.result
            finally:
                self._states.pop(id(goal_handle.request), None)
            if status == SUCCEEDED:
                goal_handle.succeed()
            elif status == CANCELED and goal_handle.is_cancel_requested:
                goal_handle.canceled()
            else:
                goal_handle.abort()
            counters.results += 1
            return result
        return execute

    def _cancel_callback(self, codec: Any):
        counters, log = self.counters[codec.id], self.w.log

        async def on_cancel(goal_handle: Any) -> CancelResponse:
            state = self._states.get(id(goal_handle.request))
            if state is None:
                return CancelResponse.REJECT
            if state.cancel is None or state.cancel.done():
                state.cancel = Future()
                state.cancel_deadline = self.w.clock.now() + codec.accept_timeout
                counters.cancels += 1
                if not self.w.send(codec.id, codec.encode_cancel(state.handle)):
                    log.error(f"{codec.name}: cancel of goal {state.handle} refused by the link")
                    state.cancel.set_result(None)
            answer = await state.cancel
            return CancelResponse.ACCEPT if answer == CANCELING else CancelResponse.REJECT
        return on_cancel

    def goal_stats(self, ident: int) -> dict:
        table = self.tables.get(ident)
        return table.stats().get(ident, {}) if table is not None else {}


def action_status(standins: ActionStandIns, servers: Any, channels: dict[int, dict],
                  unavailable: dict[str, str]) -> dict[str, dict]:
    """The `actions` section of ~/status: counters, goal handles (client side) and the
    link channels (goals/answers/results on key id, feedback on FEEDBACK_KEY_BASE + id)."""
    from dataclasses import asdict

    from uwgen.bridge.plan import FEEDBACK_KEY_BASE
    out = {}
    for codec, serving in ([(c, False) for c in standins.codecs] + [(c, True) for c in servers.codecs]):
        counters = (servers if serving else standins).counters[codec.id]
        entry = {"id": codec.id, "type": codec.type_name, "role": "server" if serving else "client",
                 **asdict(counters), "link": channels.get(codec.id, {})}
        if serving:
            entry["feedback_link"] = channels.get(FEEDBACK_KEY_BASE + codec.id, {})
            entry["in_flight"] = len(servers.goals.get(codec.id, {}))
        else:
            entry["goals_table"] = standins.goal_stats(codec.id)
        if codec.name in unavailable:
            entry["unavailable"] = unavailable[codec.name]
        out[codec.name] = entry
    return out
