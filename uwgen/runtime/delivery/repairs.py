"""What a packet's spare room and its front carry besides fresh messages (docs/wire-format.md
section 15.6): re-sends of reliable messages the peer lost, first; a reliable message's first
copy whose packet is overdue for a report, as a re-send; then, in the room left after the
fresh messages, a command's copy in its own turn (echoes.py) and a reliable message's copy
(copies.py). Called by `uwgen.runtime.delivery.reliability.Reliability` under its lock;
`resending` maps each payload handed out to the message it copies (its identity), for the
packet's `sent`."""
from __future__ import annotations

from collections import deque

from uwgen.runtime.delivery.echoes import Echoes
from uwgen.runtime.delivery.reliable import ReliableLink, Sent
from uwgen.runtime.link.packets import message_measure
from uwgen.runtime.wire.heads import Heads


class Repairs:
    def __init__(self, engine: ReliableLink, echoes: Echoes, heads: Heads,
                 deadlines: dict[int, float]):
        self.engine, self.echoes, self.heads, self.deadlines = engine, echoes, heads, deadlines
        self.queue: deque[Sent] = deque()             # lost reliable messages to send again
        self.resending: dict[int, Sent] = {}          # id(payload) -> the copy picked now

    def resend(self, now: float, room: int) -> tuple[int, bytes] | None:
        self.queue.extend(self.engine.due(now))
        for m in list(self.queue):
            if self.engine.spare.delivered(m.ident):
                self.queue.remove(m)      # a copy sent in spare room arrived meanwhile
                continue
            if m.deadline is not None and m.deadline <= now:
                self.queue.remove(m)
                self.engine.entry(m.key).expired += 1
                continue
            payload = self.aged(m, now)
            if message_measure(payload) <= room:
                self.queue.remove(m)
                self.resending[id(payload)] = m
                return m.key, payload
        # a message sent once, in a packet no report has answered for a round trip: its
        # first copy goes first, as a re-send does (wire-format.md 15.6, overdue reports)
        srtt = self.engine.rtt.srtt
        return None if srtt is None else self._copy(now, room, (self.engine.reported_at, now - srtt))

    def copy(self, now: float, room: int, fresh: bool = True) -> tuple[int, bytes] | None:
        """A copy for the room a packet that leaves anyway has left: a command of this own
        turn (echoes.py), else, beside fresh messages, a reliable message on its way (copies.py)."""
        echo = self.echoes.pick(now, room) if self.echoes.wanted() else None
        return echo if echo is not None or not fresh else self._copy(now, room)

    def _copy(self, now: float, room: int,
              unanswered: tuple[float, float] | None = None) -> tuple[int, bytes] | None:
        def fits(m: Sent) -> bytes | None:
            payload = self.aged(m, now)
            return payload if message_measure(payload) <= room else None
        got = self.engine.spare.pick(self.engine.outstanding.values(), now, fits, unanswered)
        if got is not None:
            self.resending[id(got[1])] = got[0]
        return None if got is None else (got[0].key, got[1])

    def aged(self, m: Sent, now: float) -> bytes:
        """The copy to send again, its age item rewritten to the message's age now (its
        deadline less the entry's re-send window is its publication time, section 15.4): the
        age it left with the first time would make it look younger than it is."""
        window = self.deadlines.get(m.key)
        if m.deadline is None or window is None:
            return m.ref
        return self.heads.aged_again(m.ref, now - (m.deadline - window))
