"""No orphaned goals: a server-side bridge that starts again finds the goals its predecessor
started on the local action server, and adopts them (docs/wire-format.md section 13,
"Restarts").

Every goal the server side sends its local action server has a UUID that says so, names the
link's handle and tells how the goal came: `75 77 67` ("uwg"), the action id, the handle, a
4-byte digest of the goal's payload as it came over the link (BLAKE2s), when it first came
(milliseconds of the system clock, modulo 2^40, 5 bytes big-endian), then 2 random bytes.
The local action server lists its goals on its status topic (`<action>/_action/status`,
transient local: a subscriber that comes late still gets the last list). A bridge that
starts reads it; every goal with our mark for one of its actions, still accepted,
executing or canceling, that this start did not send, was started by a predecessor that
died without finishing it (SIGKILL, a crash): it is **adopted** (a goal handle for it is
made from its UUID, its result is asked for and pushed to the client side under its handle,
and `result_timeout` is supervised as for any goal), or **cancelled** when its handle is
busy with a newer goal.

A goal that came over the link and **may copy** a goal a predecessor took (its age item
says it began before this start, `Wiring.may_predate`, `Served.may_copy`: its likely
beginning, the clock offset's error not counted, as at a start that error is most of a
second and would make every goal sent just after the start look older than it) is not sent
to the local server until the goal list is **known** (`heard_or_grace`): heard, or
`STATUS_GRACE` seconds after start (a server that never had a goal publishes none). It
would otherwise run a second time beside the running goal it copies. No guess is taken
from the status publisher's match for it: the subscription sees the publisher matched
before the publisher has matched it and sent its transient local list, a gap a loaded
machine can stretch past any fixed wait (`LIST_SETTLE`), and a copy sent on that guess runs
twice. A goal that began after this start cannot copy a predecessor's and goes as soon as
the local server is ready. A held goal that the list then shows running on its handle is
the running goal's copy: the running goal is adopted and the copy dropped (counted
`duplicate_goals`). A held goal whose wait (half its accept_timeout) ends before the list
is known is neither sent nor answered until it is (`_answer_unlisted`): then the goal it
copies answers, or it is rejected, the truth, as it never ran. On a link without age items
(wire format 1) a goal's beginning is not known: every goal waits for the list, taken as
known also once the status publisher has been matched `LIST_SETTLE` seconds with nothing
heard (`listed`), and goes when its wait is over rather than be refused for a list slow to
come (there a copy can still run twice when the list is late). The side tells the client
side that it knows no such goal only once the list was heard or `STATUS_GRACE` is over
(`heard_or_grace`): a caller told "lost" for a goal about to be adopted is lied to, so no
guess from the match there.

A goal of ours that **finished** while no bridge watched it (succeeded, aborted or cancelled
while the server side was down) is listed too, for as long as the local server keeps its
result. Of the finished goals on one handle the latest accepted is kept (goals on a handle
follow one another); a newer goal on the handle drops it (`finished_goal`, `forget`). Its
result goes to the client side in two cases, never unasked (handles are reused, so an old
result pushed unasked could complete a newer goal):

- the client side asks for the result of that handle (it keeps asking while it waits);
- a goal comes over the link on that handle that is the finished goal's **copy**
  (`repeat_of`): the same payload (its digest in the UUID), within `REPEAT_WINDOW`
  accept_timeouts of when the finished goal first came (its arrival in the UUID). The copy
  is answered accepted, the finished goal's result follows, and the copy is not run
  (counted `duplicate_goals` and `orphans_finished`). This is the rule a bridge that kept running applies to a goal
  that comes again after its answer and result were lost (`action_results.ResultBook
  .repeat_of`: same handle, same bytes, measured from the first arrival), measured from the
  same instant: the arrival is written into the UUID because the status list's stamp is
  the local server's acceptance, later than the arrival by the wait for the list and the
  local server's answer (up to half an accept_timeout, then one more), and a window
  measured from it would reach past the time the client side may give the handle to a new
  goal. The window is what separates a copy from a new goal with the same payload on a
  reused handle: the client side sends copies within one accept_timeout of the goal's first
  send and gives the handle to a new goal only 2 accept_timeouts after the old one ended
  there, so the same payload on the handle within the window is the copy, after it a new
  goal; only when all the client side's handles ended more recently does it reuse one
  sooner (calls.CallTable), and a new goal with the same payload then cannot be told from a
  copy on the wire, here as on a running bridge. Another payload is a new goal at any
  time. Only the clock differs from the running bridge's: the arrival is on the system
  clock, which a restart does not reset (an arrival that lies ahead of it, after the clock
  was set back, is outside the window).
"""
from __future__ import annotations

import hashlib
import random
from collections.abc import Callable
from typing import Any

MARK = b"uwg"
STATUS_GRACE = 10.0         # seconds after start before the list counts as known unheard
                            # (discovery of the local server can take seconds on a loaded machine)
LIST_SETTLE = 0.5           # wire format 1: seconds a matched status publisher may take to
                            # deliver its list
ACTIVE = (1, 2, 3)          # GoalStatus ACCEPTED, EXECUTING, CANCELING
FINISHED = (4, 5, 6)        # GoalStatus SUCCEEDED, CANCELED, ABORTED


ARRIVAL_MODULO = 1 << 40    # milliseconds: the arrival in a UUID wraps every 34.8 years


def digest(payload: bytes) -> bytes:
    """The 4 bytes of a goal's UUID that tell its payload (a copy has the same)."""
    return hashlib.blake2s(payload, digest_size=4).digest()


def goal_uuid(ident: int, handle: int, rng: random.Random, payload: bytes = b"",
              arrived: float = 0.0) -> bytes:
    """The 16-byte UUID of a goal the server side sends for (action id, handle), that came
    as `payload` at `arrived` (system clock, seconds since the epoch)."""
    ms = int(arrived * 1000) % ARRIVAL_MODULO
    return (MARK + bytes([ident & 0xFF, handle & 0xFF]) + digest(payload) + ms.to_bytes(5, "big")
            + bytes(rng.getrandbits(8) for _ in range(2)))


def age_of_copy(uuid: bytes, payload: bytes, now: float) -> float | None:
    """Seconds since the goal named by `uuid` first came, when `payload` is its copy (same
    digest); None when it is another goal. `now`: system clock, seconds since the epoch."""
    uuid = bytes(uuid)
    if uuid[5:9] != digest(payload):
        return None
    ms = (int(now * 1000) - int.from_bytes(uuid[9:14], "big")) % ARRIVAL_MODULO
    return ms / 1000


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
        """On a link without age items, whether the local server's goal list is taken as
        known (see the module's docstring): heard, or its publisher matched `LIST_SETTLE`
        seconds ago with nothing to say, or the grace is over. Asked on every expiry tick,
        so the match is timed from when it happened."""
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

    def repeat_of(self, handle: int, payload: bytes, now: float, window: float
                  ) -> tuple[bytes, Any, float] | None:
        """(uuid, goal info, seconds since it came) of the goal of ours on `handle` that
        finished unwatched and of which `payload` is a copy that came within `window` s of
        it (module docstring), taken; None when `payload` is a new goal. `now`: when the
        copy came, system clock, seconds since the epoch."""
        got = self.finished.get(handle)
        if got is None:
            return None
        age = age_of_copy(got[1], payload, now)
        if age is None or age > window:
            return None
        del self.finished[handle]
        return got[1], got[2], age

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
