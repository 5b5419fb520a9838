"""The replay window of one sender (one epoch of it), and the reconstruction of its numbers.

The window remembers the highest sequence number accepted (`high`) and which of the
`size` numbers below it were seen, as RFC 4303 (IPsec ESP) and DTLS do: a number above
`high` is new, one inside the window is new unless its bit is set (reordering within the
window is accepted, a duplicate is a replay), one below the window is too old.

What one frame can do is bounded (docs/seams.md section 2): a number more than `max_jump` above
`high` is refused (TOO_FAR) and moves nothing, so a key holder who forges a frame numbered
2^42 cannot push the window out of the real sender's reach.

The window also remembers when `high` moved (on the injected clock of its owner): a frame
numbered below a number that arrived at time t was sealed before t, so its age is at least
now - t (`overtaken_for`). The guard refuses such a frame once that lower bound passes the
entry's max age (a frame held back by an attacker while newer ones went through).

Frames carry only the low 11 bits of the number (sync frames carry all of it). The receiver
picks the number with those low bits that is closest to `high + 1` (RFC 9147, 4.2.2);
without any state for a sender it can only take sync frames.
"""
from __future__ import annotations

from collections import deque

from uwgen.security.wire import PARTIAL_BITS

WINDOW = 128          # positions remembered below the highest number (at least 64)
MAX_JUMP = 1 << 16    # the most one frame may move the window forward
NEW, REPLAY, TOO_OLD, TOO_FAR = "new", "replay", "too_old", "too_far"


class ReplayWindow:
    def __init__(self, size: int = WINDOW, high: int | None = None, bits: int = 0,
                 max_jump: int = MAX_JUMP):
        if size < 64:
            raise ValueError("a replay window keeps at least 64 positions")
        self.size, self.max_jump = size, max_jump
        self.high = high
        self._mask = (1 << size) - 1
        self.bits = bits & self._mask        # bit i set: number high - i was seen
        self._moves: deque[tuple[int, float]] = deque()   # (new high, when), oldest first

    @classmethod
    def from_floor(cls, floor: int, size: int = WINDOW, max_jump: int = MAX_JUMP) -> "ReplayWindow":
        """A window that treats every number up to `floor` as seen (a first contact, a restart)."""
        return cls(size, floor, (1 << size) - 1, max_jump)

    def reconstruct(self, partial: int, bits: int = PARTIAL_BITS) -> int | None:
        """The full number whose low `bits` bits are `partial` closest to high + 1; None
        without state."""
        if self.high is None:
            return None
        expected = self.high + 1
        span = 1 << bits
        base = (expected & ~(span - 1)) | partial
        candidates = [c for c in (base - span, base, base + span) if c >= 0]
        return min(candidates, key=lambda c: abs(c - expected))

    def check(self, seq: int) -> str:
        """NEW, REPLAY, TOO_OLD or TOO_FAR; changes nothing (call accept() once the tag is good)."""
        if self.high is None:
            return NEW
        if seq > self.high:
            return TOO_FAR if seq - self.high > self.max_jump else NEW
        back = self.high - seq
        if back >= self.size:
            return TOO_OLD
        return REPLAY if (self.bits >> back) & 1 else NEW

    def overtaken_for(self, seq: int, now: float) -> float | None:
        """Seconds since a number above `seq` first arrived (a lower bound of the age of the
        frame numbered `seq`), or None when none has."""
        if self.high is None or seq >= self.high:
            return None                        # nothing above it arrived yet
        for high, when in self._moves:
            if high > seq:
                return now - when
        return None

    def accept(self, seq: int, now: float = 0.0) -> None:
        if self.high is None:
            self.high, self.bits = seq, 1
        elif seq > self.high:
            shift = seq - self.high
            self.bits = ((self.bits << shift) | 1) & self._mask if shift < self.size else 1
            self.high = seq
        else:
            self.bits |= 1 << (self.high - seq)
            return
        self._moves.append((seq, now))
        while self._moves and self._moves[0][0] < self.high - self.size:
            self._moves.popleft()              # below the window: refused as too old anyway
