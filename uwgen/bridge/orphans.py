"""No orphaned goals: a server-side bridge that starts again finds the goals its predecessor
started on the local action server, and adopts them (docs/wire-format.md section 13,
"Restarts").

Every goal the server side sends its local action server has a UUID that says so and names
the link's handle: `75 77 67` ("uwg"), the action id, the handle, then 11 random bytes.
The local action server lists its goals on its status topic (`<action>/_action/status`,
transient local: a subscriber that comes late still gets the last list). A bridge that
starts reads it; every goal with our mark for one of its actions, still accepted,
executing or canceling, that this start did not send, was started by a predecessor that
died without finishing it (SIGKILL, a crash): it is **adopted** (a goal handle for it is
made from its UUID, its result is asked for and pushed to the client side under its handle,
and `result_timeout` is supervised as for any goal), or **cancelled** when its handle is
busy with a newer goal.

Until the goal list is **known** (`OrphanWatch.listed`) the server side does not send the
local server a goal that came over the link: a goal's copy that reaches a bridge started
again before the list would otherwise run a second time beside the running goal it copies.
The list is known once it has been heard, or once the status publisher has been matched for
`LIST_SETTLE` seconds with nothing heard (a transient local list comes with the match; a
server that never had a goal publishes none), or `STATUS_GRACE` seconds after start. A goal
held for the list that the list then shows running on its handle is the running goal's copy:
the running goal is adopted and the copy dropped (counted `duplicate_goals`). The side tells
the client side that it knows no such goal only once the list was heard or `STATUS_GRACE`
is over (`heard_or_grace`): a caller told "lost" for a goal about to be adopted is lied to,
so no guess from the match there.

A goal of ours that **finished** while no bridge watched it (succeeded, aborted or cancelled
while the server side was down) is listed too, for as long as the local server keeps its
result. Its result is given to the client side only when the client side asks for the result
of that handle (it keeps asking while it waits): handles are reused, so an old result pushed
unasked could complete a newer goal. Of the finished goals on one handle the latest accepted
is kept (goals on a handle follow one another); a newer goal on the handle drops it
(`finished_goal`, `forget`).
"""
from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

MARK = b"uwg"
STATUS_GRACE = 10.0         # seconds after start before the list counts as known unheard
                            # (discovery of the local server can take seconds on a loaded machine)
LIST_SETTLE = 0.5           # seconds a matched status publisher may take to deliver its list
ACTIVE = (1, 2, 3)          # GoalStatus ACCEPTED, EXECUTING, CANCELING
FINISHED = (4, 5, 6)        # GoalStatus SUCCEEDED, CANCELED, ABORTED


def goal_uuid(ident: int, handle: int, rng: random.Random) -> bytes:
    """The 16-byte UUID of a goal the server side sends for (action id, handle)."""
    return MARK + bytes([ident & 0xFF, handle & 0xFF]) + bytes(rng.getrandbits(8) for _ in range(11))


def handle_of(uuid: bytes, ident: int) -> int | None:
    """The handle a UUID of ours names for action `ident` (None: not ours, or another id)."""
    uuid = bytes(uuid)
    if len(uuid) != 16 or not uuid.startswith(MARK) or uuid[3] != ident & 0xFF:
        return None
    return uuid[4]


class OrphanWatch:
    """Reads one action's status topic and hands over the goals of a predecessor."""

    def __init__(self, node: Any, action_name: str, ident: int,
                 adopt: Callable[[int, bytes, Any], None], own: set[bytes], started: float,
                 callback_group: Any = None):
        from action_msgs.msg import GoalStatusArray
        from rclpy.qos import qos_profile_action_status_default
        self.ident, self.adopt, self.own, self.started = ident, adopt, own, started
        self.heard = False
        self.matched: float | None = None     # when the status publisher was first seen matched
        self.seen: set[bytes] = set()
        self.finished: dict[int, tuple[int, bytes, Any]] = {}   # handle -> (stamp, uuid, info)
        self.sub = node.create_subscription(GoalStatusArray, f"{action_name}/_action/status",
                                            self._status, qos_profile_action_status_default,
                                            callback_group=callback_group)

    def heard_or_grace(self, now: float) -> bool:
        """Whether "no such goal" may be said: the list was heard, or the grace is over (a
        caller told "lost" for a goal about to be adopted is lied to: no guess from the
        match here)."""
        return self.heard or now - self.started >= STATUS_GRACE

    def listed(self, now: float) -> bool:
        """Whether the local server's goal list is known (see the module's docstring): heard,
        or its publisher matched `LIST_SETTLE` seconds ago with nothing to say, or the grace
        is over. Asked on every expiry tick, so the match is timed from when it happened."""
        if self.heard or now - self.started >= STATUS_GRACE:
            return True
        if self.sub.get_publisher_count() == 0:
            self.matched = None
            return False
        if self.matched is None:
            self.matched = now
        return now - self.matched >= LIST_SETTLE

    def finished_goal(self, handle: int) -> tuple[bytes, Any] | None:
        """(uuid, goal info) of the latest goal of ours on `handle` that finished unwatched,
        taken (it is handed over once); None when there is none."""
        got = self.finished.pop(handle, None)
        return None if got is None else (got[1], got[2])

    def forget(self, handle: int) -> None:
        """A newer goal came on `handle`: a finished one's result is no longer asked for."""
        self.finished.pop(handle, None)

    def _status(self, msg: Any) -> None:
        self.heard = True
        for status in msg.status_list:
            uuid = bytes(status.goal_info.goal_id.uuid)
            handle = handle_of(uuid, self.ident)
            if handle is None or uuid in self.own or uuid in self.seen:
                continue
            if status.status in FINISHED:
                stamp = status.goal_info.stamp
                ns = stamp.sec * 1_000_000_000 + stamp.nanosec
                if ns >= self.finished.get(handle, (-1,))[0]:
                    self.finished[handle] = (ns, uuid, status.goal_info)
                continue
            if status.status not in ACTIVE:
                continue
            self.seen.add(uuid)
            self.finished.pop(handle, None)       # a goal running on it is newer
            self.adopt(handle, uuid, status.goal_info)
