"""The replay window of one sender, and the reconstruction of its sequence numbers.

The window remembers the highest sequence number accepted (`high`) and which of the
`size` numbers below it were seen, as RFC 4303 (IPsec ESP) and DTLS do: a number above
`high` is new, one inside the window is new unless its bit is set (reordering within the
window is accepted, a duplicate is a replay), one below the window is too old.

Frames carry only the low 11 bits of the number (sync frames carry all 43). The receiver
picks the number with those low bits that is closest to `high + 1` (RFC 9147, 4.2.2);
without any state for a sender it can only take sync frames.
"""
from __future__ import annotations

from uwgen.security.wire import PARTIAL_BITS, PARTIAL_MASK

WINDOW = 128          # positions remembered below the highest number (at least 64)
NEW, REPLAY, TOO_OLD = "new", "replay", "too_old"


class ReplayWindow:
    def __init__(self, size: int = WINDOW, high: int | None = None, bits: int = 0):
        if size < 64:
            raise ValueError("a replay window keeps at least 64 positions")
        self.size = size
        self.high = high
        self._mask = (1 << size) - 1
        self.bits = bits & self._mask        # bit i set: number high - i was seen

    @classmethod
    def from_floor(cls, floor: int, size: int = WINDOW) -> "ReplayWindow":
        """A window that treats every number up to `floor` as seen (after a restart)."""
        return cls(size, floor, (1 << size) - 1)

    def reconstruct(self, partial: int) -> int | None:
        """The full number ending in `partial` closest to high + 1; None without state."""
        if self.high is None:
            return None
        expected = self.high + 1
        span = 1 << PARTIAL_BITS
        base = (expected & ~PARTIAL_MASK) | partial
        candidates = [c for c in (base - span, base, base + span) if c >= 0]
        return min(candidates, key=lambda c: abs(c - expected))

    def check(self, seq: int) -> str:
        """NEW, REPLAY or TOO_OLD; changes nothing (call accept() once the tag is good)."""
        if self.high is None or seq > self.high:
            return NEW
        back = self.high - seq
        if back >= self.size:
            return TOO_OLD
        return REPLAY if (self.bits >> back) & 1 else NEW

    def accept(self, seq: int) -> None:
        if self.high is None:
            self.high, self.bits = seq, 1
        elif seq > self.high:
            shift = seq - self.high
            self.bits = ((self.bits << shift) | 1) & self._mask if shift < self.size else 1
            self.high = seq
        else:
            self.bits |= 1 << (self.high - seq)
