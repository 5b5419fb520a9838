"""The results of one served action, kept for the client side until it has them (server side).

A result is pushed once when its goal finishes, then sent again when a copy is due
(uwgen.bridge.copies: once a round under the turns MAC, else every RTO) until the client
side acknowledges it (wire format 13, *result status*) or for at most 2 accept_timeouts:
the client side gives the handle to a new goal only 2 accept_timeouts after this goal ended
there. The RECENT_RESULTS last results are also kept, with the goal's bytes, so that a goal
that comes again after its answer and result were lost gets its result again instead of a
second run, and a client side that asks for a result it missed gets it.

`Served` is the record of one goal from the link while it is at the local server.

No rclpy here: `ActionServers` decides what to send and when a goal ends; this book only
remembers, times (an injectable clock's `now` is passed in) and counts round trips.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from uwgen.runtime.delivery.reliable import RttEstimator

RECENT_RESULTS = 8        # finished goals per action whose result is kept for a repeated goal
REPEAT_WINDOW = 1.5       # accept_timeouts after a goal first came in which a copy is a repeat
                          # (the client side sends copies within one accept_timeout, and
                          # reuses a handle only 2 accept_timeouts after its goal ended)


@dataclass
class Unacked:
    """A result sent and not yet acknowledged by the client side."""

    payload: bytes
    first_sent: float
    next_send: float
    until: float                  # no copy after this: the client side may reuse the handle
    sends: int = 1
    turn: int | None = None       # own turns ended while it waited in the link (copies.py)
    held: bool = False            # timer: its first copy waited once more (copies.py)


@dataclass
class Served:
    """One goal from the link, at the real server (server side)."""

    sent: Any                     # rclpy Future of send_goal_async: -> ClientGoalHandle
    deadline: float               # (None: waiting for the local server or its goal list)
    payload: bytes = b""          # the goal as it came (a repeat has the same bytes)
    arrived: float = 0.0          # when it first came
    goal_handle: Any = None       # ClientGoalHandle, once accepted
    cancel_wanted: bool = False   # a cancel came before the local server answered
    goal: Any = None              # the goal message while it waits for the local server
    began: float | None = None    # when it began on the client side (Wiring.began)
    # did it begin before this start (orphans.py)? None: the link cannot tell (no age item)
    unsure: bool | None = None

    @property
    def may_copy(self) -> bool:
        return could_copy(self.unsure)


def could_copy(unsure: bool | None) -> bool:
    """Whether a goal may copy a goal a previous start of the bridge took, by `Served.unsure`:
    unless it is known to have begun after the start."""
    return unsure is not False


@dataclass(frozen=True)
class Finished:
    """A goal that ended here: its bytes as they came, its result payload, when it came."""

    goal: bytes
    result: bytes
    arrived: float


class ResultBook:
    """The results of one action: recent ones by handle, unacknowledged ones to send again."""

    def __init__(self, accept_timeout: float, rtt: RttEstimator):
        self.accept_timeout = accept_timeout
        self.rtt = rtt
        self.recent: OrderedDict[int, Finished] = OrderedDict()
        self.unacked: dict[int, Unacked] = {}

    def sent(self, handle: int, goal: bytes, result: bytes, arrived: float, now: float,
             turn: int | None = None) -> None:
        """The result of goal `handle` (which came as `goal` at `arrived`) went out at `now`
        (`turn`: the own turns ended then, under the turns MAC)."""
        self.recent[handle] = Finished(goal, result, arrived)
        self.recent.move_to_end(handle)
        while len(self.recent) > RECENT_RESULTS:
            self.recent.popitem(last=False)
        self.unacked[handle] = Unacked(result, now, now + self.rtt.rto, now + 2 * self.accept_timeout,
                                       turn=turn)

    def acknowledged(self, handle: int, now: float) -> Unacked | None:
        """The client side has the result: stop sending it (what waited for it; None if
        nothing did)."""
        unacked = self.unacked.pop(handle, None)
        if unacked is None:
            return None
        if unacked.sends == 1:        # Karn: only an unambiguous round trip is a sample
            self.rtt.sample(now - unacked.first_sent)
        return unacked

    def forget(self, handle: int) -> None:
        """A new goal on `handle`: what the old one left is no longer asked for."""
        self.recent.pop(handle, None)
        self.unacked.pop(handle, None)

    def stop_sending(self, handle: int) -> None:
        """The client side gave the goal up (it cancelled a goal that had finished here)."""
        self.unacked.pop(handle, None)

    def result_of(self, handle: int) -> bytes | None:
        """The result payload of a recent goal, else None."""
        recent = self.recent.get(handle)
        return None if recent is None else recent.result

    def repeat_of(self, handle: int, goal: bytes, now: float) -> bytes | None:
        """The result to send again when `goal` is a copy of a goal that finished here lately
        (same handle, same bytes, within REPEAT_WINDOW accept_timeouts of its arrival)."""
        recent = self.recent.get(handle)
        if recent is None or recent.goal != goal or now - recent.arrived > REPEAT_WINDOW * self.accept_timeout:
            return None
        return recent.result

    def due(self, now: float, ready: Callable[[Unacked], bool] | None = None
            ) -> Iterator[bytes | None]:
        """The results to send again now, each once more; None for each one given up (2
        accept_timeouts passed without an acknowledgement: counted `results_unacked`).
        `ready`: whether a result's copy is due (uwgen.bridge.copies); default its timer."""
        for handle, unacked in list(self.unacked.items()):
            if now >= unacked.until:
                del self.unacked[handle]
                yield None
                continue
            if not (unacked.next_send <= now if ready is None else ready(unacked)):
                continue
            self.rtt.backoff()
            unacked.sends += 1
            unacked.next_send = now + self.rtt.rto
            yield unacked.payload
