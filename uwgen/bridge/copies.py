"""When the bridge sends a command again, and a copy taken back when its answer comes first
(docs/wire-format.md sections 5, 13 and 15.6; docs/seams.md section 7).

A command (a service request, a goal, a result) unanswered is sent again:
- on a link with a MAC (turns or slots), by the link (`link_resends`; which ids:
  `uwgen.bridge.reliability.reliable_commands`): the peer's reports name each lost packet
  in its next turn, and the link sends again just what they name lost, in this side's next
  turn, until the command's deadline. Whether the request or the answer was lost, only
  that leg goes again: a fixed timer cannot know the answer waits for the peer's turn, so
  it sends copies before the answer can be back, or a whole round late. The bridge's own
  copy then comes only once that deadline has passed (what the link cannot carry: a peer
  that restarted and lost what it had);
- without a MAC, by the bridge after the command's retransmission timeout
  (`uwgen.runtime.delivery.reliable.command_rtt`).

A copy still queued is taken back from the link (`Link.withdraw`) the moment its answer
arrives, on the link's thread, before the link writes again: `heard` sees every payload as
the link delivers it, ahead of the executor. Each copy names the payload head that answers
it (`answered_by`): a response `[3, id, seq]` answers request `[2, id, seq, ...]`, an answer
or result `[3, id, handle]` a goal, a result status `[2, id, 24 + handle, 0]` a result. A copy
whose earlier one still waits in the link's queue adds nothing (the one queued goes), and one
whose answer was heard and is not yet handled is not sent.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable

from uwgen.runtime.delivery.reliable import RttEstimator

LINK_RESENDS_SHARE = 4  # of a command's largest RTO (a quarter of its deadline): while the
                        # link sends it again (until that deadline) the bridge sends no copy
KEPT = 256              # copies waiting to be taken back, answers heard lately (each bounded)

SENT, QUEUED, ANSWERED = "sent", "queued", "answered"


@dataclass
class Due:
    """When a command's next copy is due."""

    time: float


def uint_at(payload: bytes, at: int) -> tuple[int, int]:
    """The CBOR unsigned integer starting at `at` and where it ends ((0, -1): not one)."""
    if at >= len(payload) or payload[at] >> 5 != 0:
        return 0, -1
    extra = payload[at] & 0x1F
    size = 0 if extra < 24 else {24: 1, 25: 2, 26: 4, 27: 8}.get(extra, -1)
    if size < 0 or at + 1 + size > len(payload):
        return 0, -1
    value = extra if size == 0 else int.from_bytes(payload[at + 1:at + 1 + size], "big")
    return value, at + 1 + size


def answered_by(payload: bytes) -> bytes | None:
    """The head of what answers a command's payload (None: not a command): a request or goal
    `[2, id, n, ...]` is answered by `[3, id, n, ...]`, a result `[3, id, handle, status,
    ...]` by its status `[2, id, 24 + handle, 0]`."""
    if not payload or payload[0] not in (2, 3):
        return None
    _, id_end = uint_at(payload, 1)
    n, end = uint_at(payload, id_end) if id_end > 0 else (0, -1)
    if end < 0:
        return None
    if payload[0] == 2:
        return b"\x03" + bytes(payload[1:end])
    return b"\x02" + bytes(payload[1:id_end]) + bytes((0x18, 24 + n, 0))


class Copies:
    """A side's command copies (module doc). `send(key, payload) -> accepted` and
    `withdraw(key, payload) -> taken back` are the link's. `heard` runs on the link's
    thread, the rest on the executor's."""

    def __init__(self, send: Callable[[int, bytes], bool], withdraw: Callable[[int, bytes], bool],
                 link_resends: bool = False):
        self._send, self._withdraw = send, withdraw
        self.link_resends = link_resends
        self._lock = threading.Lock()
        self._waiting: OrderedDict[bytes, tuple[int, bytes]] = OrderedDict()  # answer head -> copy
        self._heard: OrderedDict[bytes, None] = OrderedDict()   # answer heads heard lately

    def due(self, now: float, rtt: RttEstimator) -> Due:
        """When the copy after one sent now is due."""
        if self.link_resends:
            return Due(now + LINK_RESENDS_SHARE * rtt.maximum)
        return Due(now + rtt.rto)

    def is_due(self, due: Due, now: float) -> bool:
        return now >= due.time

    def send(self, key: int, payload: bytes) -> str:
        """Send a copy of `payload`: SENT; QUEUED when the one sent before still waits in the
        link's queue (nothing added); ANSWERED when its answer was heard (nothing sent)."""
        answer = answered_by(payload)
        with self._lock:
            if answer is not None and answer in self._heard:
                return ANSWERED
            if self._withdraw(key, payload):
                self._send(key, payload)        # it never left: it goes where it was going
                return QUEUED
            if answer is not None:
                self._waiting[answer] = (key, payload)
                while len(self._waiting) > KEPT:
                    self._waiting.popitem(last=False)
        self._send(key, payload)
        return SENT

    def heard(self, payload: bytes) -> None:
        """A payload the link delivered (its thread): take back the copy it answers."""
        if not payload or payload[0] not in (2, 3):
            return
        with self._lock:
            for answer in [a for a in self._waiting if payload.startswith(a)]:  # CBOR heads
                key, copy = self._waiting.pop(answer)                            # end themselves
                self._withdraw(key, copy)
                self._heard[answer] = None
                while len(self._heard) > KEPT:
                    self._heard.popitem(last=False)

    def forget(self, payload: bytes) -> None:
        """The command was answered or given up (executor): nothing to take back for it."""
        answer = answered_by(payload)
        with self._lock:
            self._waiting.pop(answer, None)
            self._heard.pop(answer, None)
