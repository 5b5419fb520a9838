"""Copies of reliable messages in spare room (docs/wire-format.md section 15.6). Pure: the
engine (`uwgen.runtime.delivery.reliable.ReliableLink`) tells it what left and what settled.

Every reliable message has an identity (`Sent.ident`) that all its copies share: the first
one, a copy sent with room to spare, a copy sent again after a loss. `Copies` knows how many
are on their way (in packets neither settled nor timed out) and which arrived, so a lost copy
goes again only when no other is on its way and none arrived. It also measures this side's
loss (the share of its last LOSS_WINDOW settled packets the peer reported missing): copies
are sent once it reaches COPY_LOSS, when the 95th percentile of a reliable topic's latency
is a message that waited for a report and a re-send (a round trip, and under a MAC a turn
or a frame, more) unless a copy went with it. How many copies a message gets follows the
loss: one from COPY_LOSS (at 10 % loss, it and its copy are lost together 1 time in 100),
two from SECOND_COPY_LOSS, three from THIRD_COPY_LOSS (at 20 %, 1 in 625 instead of 1 in
125 with two). Messages that share a turn or a slot share its room (two new messages in a
turn of four packets get one copy each, whatever the loss), so the third copy is the room
a message alone in its turn has left: under a MAC a message lost with all its copies waits
a round for its report and its re-send, past twice the round trip, and at 20 % those must
stay under 1 in 20 of all messages. The message with the fewest copies so far goes first,
so a further copy never takes the room a first copy of another message needs, then the one
whose last copy left longest ago.
"""
from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable, Iterable
from itertools import islice
from typing import Any

COPY_LOSS = 0.05        # measured loss from which copies go in spare room
SECOND_COPY_LOSS = 0.1  # measured loss from which a message gets two copies
THIRD_COPY_LOSS = 0.15  # measured loss from which a message gets three copies
LOSS_WINDOW = 64        # settled packets the measured loss is counted over
DONE_KEPT = 1024        # reliable messages known delivered, remembered
COPIED_KEPT = 2048      # messages copied, remembered (those never settled are forgotten)
MEASURED = 16          # settled packets before the measured loss says anything
SCAN = 32               # the most recent packets on their way a copy is looked for in


class Copies:
    def __init__(self, limit: int = 3):
        self.limit = limit                  # most copies in spare room per message
        self.live: dict[int, int] = {}      # ident -> copies on their way
        self.done: OrderedDict[int, None] = OrderedDict()   # idents known delivered
        self.copied: dict[int, int] = {}    # ident -> copies sent in spare room since its
        self.sent = 0                       # last re-send; all copies sent in spare room
        self._next = 0
        self._recent: deque[bool] = deque(maxlen=LOSS_WINDOW)   # settled packets: arrived?
        self._recent_lost = 0

    def new_ident(self) -> int:
        ident, self._next = self._next, self._next + 1
        return ident

    def loss(self) -> float:
        """The share of the last LOSS_WINDOW settled packets reported missing (fewer settled
        so far count as arrived: a start never looks lossy)."""
        return self._recent_lost / LOSS_WINDOW

    def measured(self) -> bool:
        """Whether enough packets have settled for the loss to say something (MEASURED)."""
        return len(self._recent) >= MEASURED

    def wanted(self) -> int:
        """Copies a message gets now: none below COPY_LOSS, one, two from SECOND_COPY_LOSS,
        three from THIRD_COPY_LOSS (at most `limit`)."""
        loss = self.loss()
        return min(self.limit, sum(loss >= step for step in (COPY_LOSS, SECOND_COPY_LOSS,
                                                             THIRD_COPY_LOSS)))

    def settled(self, arrived: bool) -> None:
        if len(self._recent) == LOSS_WINDOW and not self._recent[0]:
            self._recent_lost -= 1
        self._recent.append(arrived)
        self._recent_lost += not arrived

    def went(self, messages: Iterable[Any]) -> None:
        """A packet left carrying `messages` (engine `Sent`s)."""
        for m in messages:
            if m.ident is not None:
                self.live[m.ident] = self.live.get(m.ident, 0) + 1

    def gone(self, packet: Any) -> None:
        """`packet` is no longer on its way (settled, timed out or given up on)."""
        if packet.timed_out:
            return                          # its copies left `live` when it timed out
        for m in packet.messages:
            if m.ident is not None:
                left = self.live.pop(m.ident, 0) - 1
                if left > 0:
                    self.live[m.ident] = left

    def arrived(self, m: Any) -> None:
        if m.ident is not None:
            self.done[m.ident] = None
            self.copied.pop(m.ident, None)
            while len(self.done) > DONE_KEPT:
                self.done.popitem(last=False)

    def delivered(self, ident: int | None) -> bool:
        return ident is not None and ident in self.done

    def needed(self, m: Any) -> bool:
        """Whether message `m`, whose copy was lost, must go again: none arrived and none
        is on its way (then it may be copied again after it goes)."""
        if self.delivered(m.ident) or self.live.get(m.ident, 0) > 0:
            return False
        self.copied.pop(m.ident, None)
        return True

    def pick(self, packets: Any, now: float, fits: Callable[[Any], bytes | None],
             unanswered: tuple[float, float] | None = None) -> tuple[Any, bytes] | None:
        """The copy to put in spare room, or None: a reliable message on its way (in the SCAN
        most recently sent packets), not known delivered, with fewer than `wanted()` copies
        since it last went again and its deadline ahead, whose copy `fits` (the copy's bytes,
        or None) the room; the one with the fewest copies so far, then the one whose last copy
        left longest ago (the nearest to the slow end of the latencies: in a turn or slot of
        several new messages, the copy of the one that waited longest for it goes first).
        `unanswered` (after, before): only a message not copied yet, in a packet sent
        between the two (`Reliability.resend`: its report is overdue)."""
        wanted = self.wanted() if unanswered is None else min(1, self.wanted())
        if wanted <= 0:
            return None
        candidates: dict[int, tuple[int, int, Any]] = {}
        for age, packet in enumerate(islice(reversed(packets), SCAN)):
            if packet.timed_out or (unanswered is not None
                                    and not unanswered[0] < packet.at <= unanswered[1]):
                continue
            for m in packet.messages:
                if (m.ident is None or m.ident in self.done or m.ident in candidates
                        or self.copied.get(m.ident, 0) >= wanted
                        or (m.deadline is not None and m.deadline <= now)):
                    continue
                candidates[m.ident] = (self.copied.get(m.ident, 0), age, m)
        for _copies, _age, m in sorted(candidates.values(), key=lambda c: (c[0], -c[1])):
            payload = fits(m)
            if payload is not None:
                self.copied[m.ident] = self.copied.get(m.ident, 0) + 1
                while len(self.copied) > COPIED_KEPT:
                    self.copied.pop(next(iter(self.copied)))
                self.sent += 1
                return m, payload
        return None
