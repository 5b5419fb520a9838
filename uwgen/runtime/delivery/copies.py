"""Copies of reliable messages in spare room (docs/wire-format.md section 15.6). Pure: the
engine (`uwgen.runtime.delivery.reliable.ReliableLink`) tells it what left and what settled.

Every reliable message has an identity (`Sent.ident`) that all its copies share: the first
one, a copy sent with room to spare, a copy sent again after a loss. `Copies` knows how many
are on their way (in packets neither settled nor timed out) and which arrived, so a lost copy
goes again only when no other is on its way and none arrived. It also measures this side's
loss (the share of its last LOSS_WINDOW settled packets the peer reported missing): copies
are sent once it reaches COPY_LOSS, when the 95th percentile of a reliable topic's latency
is a message that waited for a report and a re-send (a round trip, and under a MAC a turn
or a frame, more) unless a copy went with it. At 20 % loss a copy in the same turn makes
that 1 message in 25 instead of 1 in 5.
"""
from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable, Iterable
from itertools import islice
from typing import Any

COPY_LOSS = 0.05        # measured loss from which copies go in spare room
LOSS_WINDOW = 64        # settled packets the measured loss is counted over
DONE_KEPT = 1024        # reliable messages known delivered, remembered
COPIED_KEPT = 2048      # messages copied, remembered (those never settled are forgotten)
SCAN = 32               # the most recent packets on their way a copy is looked for in


class Copies:
    def __init__(self, limit: int = 1):
        self.limit = limit                  # copies in spare room per message and loss
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

    def pick(self, packets: Any, now: float,
             fits: Callable[[Any], bytes | None]) -> tuple[Any, bytes] | None:
        """The copy to put in spare room, or None: a reliable message on its way (in the SCAN
        most recently sent packets, the newest first), not known delivered, with fewer than `limit` copies since it
        last went again and its deadline ahead, whose copy `fits` (the copy's bytes, or None)
        the room; only once the measured loss is COPY_LOSS or more."""
        if self.limit <= 0 or self.loss() < COPY_LOSS:
            return None
        for packet in islice(reversed(packets), SCAN):
            if packet.timed_out:
                continue
            for m in packet.messages:
                if (m.ident is None or m.ident in self.done
                        or self.copied.get(m.ident, 0) >= self.limit
                        or (m.deadline is not None and m.deadline <= now)):
                    continue
                payload = fits(m)
                if payload is not None:
                    self.copied[m.ident] = self.copied.get(m.ident, 0) + 1
                    while len(self.copied) > COPIED_KEPT:
                        self.copied.pop(next(iter(self.copied)))
                    self.sent += 1
                    return m, payload
        return None
