"""What a server-side bridge that starts again does with the goals the local action server's
goal list shows (uwgen.bridge.orphans says when and why; docs/wire-format.md section 13,
"Restarts"): a running goal of a predecessor is adopted, or cancelled when its handle carries
a newer goal; a goal that finished while no bridge watched it hands its kept result to the
client side when asked, or when its copy comes; a goal held for a local server that did not
appear before the list was known is answered from the list once it is. The half of
`uwgen.bridge.action_servers.ActionServers` that takes goals over; the rest of that class
sets up what these read.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rclpy.task import Future

from uwgen.bridge.action_results import REPEAT_WINDOW, Served
from uwgen.runtime.wire.table import ACCEPTED

if TYPE_CHECKING:
    from uwgen.bridge.counters import ActionCounters
    from uwgen.bridge.orphans import OrphanWatch
    from uwgen.bridge.wiring import Wiring


class GoalAdoption:
    """Goals taken over from the local server's list. `ActionServers` sets up what these
    read (the wiring, per action id its (codec, ActionClient), goals by handle, counters and
    goal-list reader, and the UUIDs this start sent) and gives `_answer` (a goal answer to
    the client side), `_reject_unserved` (a goal no local server took: rejected) and
    `_finished` (a goal's result from the local server)."""

    w: Wiring
    served: dict[int, tuple[Any, Any]]
    goals: dict[int, dict[int, Served]]
    counters: dict[int, ActionCounters]
    watches: dict[int, OrphanWatch]
    own_uuids: set[bytes]

    def _adopt(self, ident: int, handle: int, uuid: bytes, info: Any, done: bool = False,
               payload: bytes = b"", arrived: float | None = None) -> None:
        """A goal a previous start of this bridge sent the local server, still running: adopt
        it (its result goes to the client side under its handle), or cancel it when its
        handle is busy with a newer goal (orphans.py). `done`: it finished while no bridge
        watched it, and the client side asks for its result or copies it: the local server's
        kept result (get_result) goes to it, kept as the goal's (`payload` as it came at
        `arrived`) for its later copies."""
        from rclpy.action.client import ClientGoalHandle
        from unique_identifier_msgs.msg import UUID
        codec, client = self.served[ident]
        response = codec.ros_class().Impl.SendGoalService.Response(accepted=True, stamp=info.stamp)
        goal_handle = ClientGoalHandle(client, UUID(uuid=list(uuid)), response)
        self.own_uuids.add(uuid)
        held = self.goals[ident].get(handle)
        if held is not None and held.sent is None and held.may_copy:
            # held for the list (on_request): the copy of this goal, not a new one
            del self.goals[ident][handle]
            self.counters[ident].duplicate_goals += 1
        elif handle in self.goals[ident]:
            self.counters[ident].orphans_cancelled += 1
            self.w.log.warning(f"{codec.name}: a goal (handle {handle}) that a previous start of "
                               "this bridge left on the local server is cancelled: its handle "
                               "carries a newer goal")
            client._cancel_goal_async(goal_handle)
            return
        now = self.w.clock.now()
        sent: Future = Future()
        sent.set_result(goal_handle)
        arrived = now if arrived is None else arrived
        self.goals[ident][handle] = Served(sent, now + codec.result_timeout, payload=payload,
                                           arrived=arrived, goal_handle=goal_handle,
                                           began=self.w.began(payload, arrived))
        if done:
            self.counters[ident].orphans_finished += 1
            self.w.log.warning(f"{codec.name}: goal {handle} finished on the local server while "
                               "this bridge was down; its result, kept by the server, goes to "
                               "the client side")
        else:
            self.counters[ident].orphans_adopted += 1
            self.w.log.warning(f"{codec.name}: adopted goal {handle}, which a previous start of "
                               "this bridge left running on the local server: its result goes "
                               f"to the client side, and it is cancelled if not done within "
                               f"{codec.result_timeout:g} s")
        goal_handle.get_result_async().add_done_callback(
            lambda f: self._finished(ident, handle, goal_handle, f))

    def _copy_of_finished(self, ident: int, handle: int, payload: bytes, came: float) -> bool:
        """Whether `payload`, come at `came`, copies a goal that finished on the local server
        while no bridge watched it, by the rule of ResultBook.repeat_of (orphans.py); if so
        it is answered accepted and the goal's kept result follows (counted duplicate_goals
        by the caller, or by _adopt for a held copy)."""
        window = REPEAT_WINDOW * self.served[ident][0].accept_timeout
        found = self.watches[ident].repeat_of(handle, payload, self.w.wall_at(came), window)
        if found is None:
            return False
        uuid, info, age = found
        self._adopt(ident, handle, uuid, info, done=True, payload=payload, arrived=came - age)
        self._answer(ident, handle, ACCEPTED)                 # its answer was lost
        return True

    def _answer_unlisted(self, ident: int, handle: int, payload: bytes, arrived: float) -> None:
        """A goal whose wait for a local server ended before the server's goal list was known,
        now that it is: the running goal it copies was adopted (its result answers), or the
        finished one it copies answers; else no server ran it: rejected."""
        if handle in self.goals[ident]:
            return                        # adopted from the list, or a newer goal came
        if self._copy_of_finished(ident, handle, payload, arrived):
            self.counters[ident].duplicate_goals += 1
            return
        self._reject_unserved(ident, handle, listless=self.served[ident][1].server_is_ready())
