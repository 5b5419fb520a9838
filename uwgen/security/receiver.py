"""The receiving rules of the secure link, shared by every seal that uses them (today's
per-payload seal, wire format 2's per-packet seal): which epoch and number a frame is under,
whether it is fresh, and whether its number is new.

`Receiver.admit(numbering, max_age, verify)` takes what a frame says about its number (sender,
low bits, and for a sync frame the full number, epoch and time) and `verify(aead, number)`,
which checks the frame's tag under a working key and number and returns what the frame
protects (or None). It returns that, or the drop reason:

- a sync frame must be fresh (`stale`); an epoch never heard is taken only from a sync frame
  sealed after this side started (`before_start`: a replay, or a frame still on its way when
  this side started; it cannot tell which) and numbered below `EPOCH_NUMBERS` (`too_far`);
  every number below that frame's counts as seen. An epoch this side let go (pushed out by
  newer ones) is taken back from a sync frame under the window it had (a replay stays one);
- a frame without a sync word needs a known epoch (`unsynced`) and is tried under the most
  recent first, its number reconstructed from its low bits;
- the tag (`bad_tag`), then the epoch's replay window (`replay`, `too_old`, `too_far`) and the
  overtaken age (`stale`: a frame numbered below one that arrived more than `max_age` ago).
- a verified frame that moves the window more than `SHADOW_JUMP` forward (only a key holder
  sends one, or a sender after that many lost) leaves the window it moved from as the epoch's
  *shadow*: frames that verify only there (the real sender, still counting from where it was)
  are taken under it, with the same replay rules, moving it at most `SHADOW_JUMP` at a time, so
  such a jump cannot lock the real sender out (docs/security.md).

Pure: clocks, the key derivation and the tag check are passed in.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uwgen.runtime.clock import Clock
from uwgen.security.epochs import EPOCH_NUMBERS, PeerEpoch, PeerEpochs
from uwgen.runtime.delivery.freshness import Freshness
from uwgen.security.wire import Sync
from uwgen.security.window import NEW, TOO_OLD, WINDOW, ReplayWindow

SHADOW_JUMP = 2048        # a forward move beyond what 12 low bits reach keeps the old window


@dataclass(frozen=True)
class Numbering:
    """What a frame says about its number."""

    sender: int
    partial: int             # the number's low `bits` bits
    bits: int                # 11 in a protected payload (wire format 1), 12 in a packet's W
    full: int | None = None  # the whole number, in a sync frame
    sync: Sync | None = None


class Receiver:
    def __init__(self, peers, aead_for: Callable[[int, bytes], Any], freshness: Freshness,
                 clock: Clock, wall: Clock, window: int = WINDOW,
                 on_new_epoch: Callable[[int], None] = lambda sender: None):
        self._peers = {s: PeerEpochs() for s in peers}
        self._aead_for, self.freshness = aead_for, freshness
        self.clock, self.wall, self._window = clock, wall, window
        self.on_new_epoch = on_new_epoch
        self.started = wall.now()            # recorded frames are older than this

    def peer(self, sender: int) -> PeerEpochs:
        return self._peers[sender]

    def admit(self, n: Numbering, max_age: float, verify: Callable[[Any, int], Any],
              time_checked: bool = False) -> Any:
        """What `verify` returned for the frame, or the drop reason (a str). `time_checked`:
        the caller judged the sync frame's time already (the per-packet seal, with the
        sender's measured clock offset)."""
        peer = self._peers[n.sender]
        if n.sync is not None:
            wall = self.wall.now()
            if not time_checked and not self.freshness.fresh(n.sync.time, wall, max_age):
                return "stale"
            entry, seq = peer.get(n.sync.epoch), n.full
            if entry is None:
                entry = peer.retired(n.sync.epoch)   # let go: back under its old window
            if entry is None:                # a new epoch: taken only from a fresh sync frame
                if self.freshness.before(n.sync.time, wall, self.started):
                    return "before_start"    # sealed before this side started
                if seq >= EPOCH_NUMBERS:     # no sender gets that far in one epoch
                    return "too_far"
                entry = PeerEpoch(n.sync.epoch, self._aead_for(n.sender, n.sync.epoch), None)
            got = verify(entry.aead, seq)
        else:
            if peer.current is None:
                return "unsynced"
            got = None
            for entry in peer.recent():      # most recent epoch first
                seq = entry.window.reconstruct(n.partial, n.bits)
                if (got := verify(entry.aead, seq)) is not None:
                    break
            else:                            # then where each was before a jump
                for entry in peer.recent():
                    if entry.shadow is not None:
                        seq = entry.shadow.reconstruct(n.partial, n.bits)
                        if (got := verify(entry.aead, seq)) is not None:
                            return self._take(peer, entry, entry.shadow, seq, max_age, got, True)
        if got is None:
            return "bad_tag"
        if entry.window is None:             # first frame of this epoch: nothing before it
            entry.window = ReplayWindow.from_floor(seq, self._window)
            self.on_new_epoch(n.sender)
            entry.window.accept(seq, self.clock.now())
            peer.touch(entry)
            return got
        window, shadowed = entry.window, False
        if entry.shadow is not None and window.check(seq) == TOO_OLD:
            window, shadowed = entry.shadow, True      # a sync frame of the real sender
        return self._take(peer, entry, window, seq, max_age, got, shadowed)

    def authentic(self, n: Numbering, verify: Callable[[Any, int], Any]) -> bool:
        """Whether the frame's tag verifies under an epoch of its sender, taking nothing (no
        window moves): for a frame refused before its tag was checked (its time), so that
        what is said about its sender's clock is said of the sender's own frames only."""
        peer = self._peers[n.sender]
        if n.sync is not None:
            entry = peer.get(n.sync.epoch) or peer.retired(n.sync.epoch)
            aead = entry.aead if entry is not None else self._aead_for(n.sender, n.sync.epoch)
            return verify(aead, n.full) is not None
        return any(verify(entry.aead, window.reconstruct(n.partial, n.bits)) is not None
                   for entry in peer.recent() for window in (entry.window, entry.shadow)
                   if window is not None)

    def _take(self, peer: PeerEpochs, entry: PeerEpoch, window: ReplayWindow, seq: int,
              max_age: float, got: Any, shadowed: bool) -> Any:
        """The replay and overtaken checks in `window` (the epoch's, or its shadow), then take."""
        now = self.clock.now()
        verdict = window.check(seq)
        if verdict == NEW and shadowed and seq - window.high > SHADOW_JUMP:
            verdict = "too_far"                # the shadow never jumps
        if verdict != NEW:
            return verdict
        overtaken = window.overtaken_for(seq, now)
        if overtaken is not None and overtaken > max_age:
            return "stale"
        if not shadowed and entry.shadow is None and seq - window.high > SHADOW_JUMP:
            entry.shadow = ReplayWindow(window.size, window.high, window.bits, window.max_jump)
        window.accept(seq, now)
        peer.touch(entry)
        return got
