"""A command's copy in its own turn (docs/wire-format.md section 15.6, "A command's copy in
its own turn"). Pure: `uwgen.runtime.delivery.reliability.Reliability` tells it what left and
what the bridge sends again, and asks it for a copy.

A command message (a service's request or response; an action's goal, answer, result,
result request or cancel) leaves once; the bridge sends it again when a round brought no
answer (`uwgen.bridge.copies`). Under a MAC a round is seconds (a turn and the peer's, or a
frame), so at 20 % loss, where a request, its answer and under turns the grant between them
each fail one time in five, a call gets about 0.6 of a chance a round, and a 12 s deadline
holds 3 to 4 rounds: about 2 calls in 100 fail. A command that has already lost a round is
the one whose next loss fails it: what the bridge sends again (`repeat`) also goes once more
in the room a later packet of the **same own turn or slot** leaves after its fresh messages,
so each of its legs fails one time in 25 and a round about one in 8. Copies go only at the
loss from which reliable topics get theirs (`copies.COPY_LOSS`), or while too few packets have
settled for the loss to be known (`copies.MEASURED`: a start, taken for lossy), within
`window` seconds of the packet that carried the command (the MAC's `own_span`: a turn's
packets, a TDMA slot; a later turn is the bridge's copy). They may ride a packet that leaves
for its parts alone, and a follower writes one more packet of its turn for one. The
receiver's bridge already takes a command twice (by its seq or handle). The copy's age item
is the command's age when it leaves. Oldest first; one copy a message; a message cut across
packets is not copied.
"""
from __future__ import annotations

from collections import OrderedDict, deque
from typing import Any

from uwgen.runtime.link.packets import message_measure
from uwgen.runtime.wire.heads import HeadError, Heads

KEPT = 16       # command messages remembered for a copy (a turn carries a few)
REPEATS = 32    # the bridge's repeats remembered until they leave


class Echoes:
    """Command messages sent in this side's turn, for one copy each in its spare room."""

    def __init__(self, keys: frozenset[int], window: float, heads: Heads, spare: Any):
        self.keys, self.window = keys, window     # the commands' channel keys (not feedback)
        self.heads = heads                        # the link's heads: the age item's place
        self.spare = spare                        # the link's copies.Copies: its measured loss
        self._repeats: OrderedDict[tuple[int, bytes], None] = OrderedDict()   # (key, payload)
        self._recent: deque[tuple[int, int, bytes, float]] = deque(maxlen=KEPT)  # number, key, payload, at
        self._picked: set[int] = set()        # id() of the copies handed out for this packet
        # the packet being built: id() of its commands that get a copy -> (key, payload) as
        # the bridge offered it (read once, in `carrying`; `left` records them)
        self._building: dict[int, tuple[int, bytes]] = {}
        self.sent: dict[int, int] = {}         # channel key -> copies sent
        self.bytes: dict[int, int] = {}        # channel key -> bytes of its copies

    def repeat(self, key: int, payload: bytes) -> None:
        """The bridge offers `payload` (as it offered it: no head) on `key` again: its first
        went without an answer, or the peer asked for it again. It gets its copy."""
        self._repeats[(key, bytes(payload))] = None
        while len(self._repeats) > REPEATS:
            self._repeats.popitem(last=False)

    def _repeated(self, key: int, payload: bytes) -> tuple[int, bytes] | bool:
        """Whether a command leaving now gets its copy: its entry in the repeats (key, the
        payload as offered), or False."""
        if key not in self.keys or id(payload) in self._picked:
            return False
        try:
            bare = (key, self.heads.take(payload).payload)
        except HeadError:
            return False
        return bare if bare in self._repeats else False

    def carrying(self, picked: list[tuple[int, bytes]]) -> None:
        """The packet being built carries `picked`: a command among them that gets its copy
        will wait for it (`waiting`), so the turn is not ended on this packet."""
        self._building = {}
        if self.window > 0:
            for key, payload in picked:
                got = self._repeated(key, payload)
                if got is not False:
                    self._building[id(payload)] = got

    def left(self, number: int, picked: list[tuple[int, bytes]], now: float) -> None:
        """Packet `number` left now carrying `picked` ((key, payload): copies among them are
        not copied again)."""
        building, self._building = self._building, {}
        for key, payload in picked:
            # read in `carrying` when it was told of this packet
            got = building[id(payload)] if id(payload) in building else self._repeated(key, payload)
            if got is not False and self.window > 0:
                self._repeats.pop(got, None)          # copied once: off the list
                self._recent.append((number, key, payload, now))
        self._picked.clear()

    def cut(self, number: int) -> None:
        """Packet `number`'s last message was cut: its tail is in the next packet, and a copy
        of its whole would not fit a packet's spare room anyway."""
        if self._recent and self._recent[-1][0] == number:
            self._recent.pop()

    def wanted(self) -> bool:
        """Whether copies go now: at a loss reliable topics' copies go at, or while the loss
        is not known yet."""
        return self.spare.wanted() > 0 or not self.spare.measured()

    def waiting(self, now: float) -> bool:
        """Whether a command of this turn still waits for its copy, when `wanted`: the side
        writes one more packet of its turn for it (a follower whose answer went alone; the
        next packet of a leader's turn is its notice or grant, which leaves anyway)."""
        return self.wanted() and (bool(self._building) or any(
            now - at <= self.window for _n, _k, _p, at in self._recent))

    def pick(self, now: float, room: int) -> tuple[int, bytes] | None:
        """The copy for `room` bytes of spare room, or None: the oldest command sent within
        `window` whose copy fits."""
        while self._recent and now - self._recent[0][3] > self.window:
            self._recent.popleft()
        for i, (_number, key, payload, at) in enumerate(self._recent):
            copy = self._older(payload, now - at)
            if message_measure(copy) <= room:
                del self._recent[i]
                self._picked.add(id(copy))
                self.sent[key] = self.sent.get(key, 0) + 1
                self.bytes[key] = self.bytes.get(key, 0) + len(copy)
                return key, copy
        return None

    def stats(self) -> dict:
        return {"command_copies": dict(self.sent), "command_copy_bytes": dict(self.bytes)}

    def _older(self, payload: bytes, later: float) -> bytes:
        """`payload` with its age item (if its entry has one) `later` seconds older."""
        try:
            age = self.heads.take(payload).age
        except HeadError:
            return payload
        return payload if age is None else self.heads.aged_again(payload, age + later)
