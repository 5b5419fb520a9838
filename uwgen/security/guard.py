"""LinkGuard: what a link calls to protect outgoing payloads and check incoming ones.

`protect(id, payload)` is called when a whole payload is taken to be sent (before it is
fragmented). It seals under this side's current epoch (epochs.SendSession): nothing on disk
decides a nonce. `unprotect(payload)` is called on every whole payload after reassembly: for
an id whose mode is sign or encrypt it returns the unprotected payload only when the tag is
good, the frame is fresh and its number is new to the (sender, epoch)'s replay window; every
other frame for such an id is dropped and counted by reason (droplog.DropLog). Payloads of
unprotected or unknown ids pass unchanged (the bridge routes and counts them as before); a
payload without a readable header is dropped (`malformed`).

Freshness without trusting a disk: a receiver takes a new epoch of a sender (after its own
start, or the sender's) only from a sync frame whose authenticated time is within the entry's
max age and sealed after this side started (freshness.Freshness), and then treats every number
up to that frame's as seen: a receiver that lost everything takes no frame recorded before it
started. A frame numbered below one that arrived more than the max age ago is refused too
(`stale`). A side that hears a new epoch of a peer makes its own next 3 frames sync frames, so a
restarted peer that sends anything hears this side again at once.
"""
from __future__ import annotations


from uwgen.runtime.clock import SYSTEM_CLOCK, Clock, WALL_CLOCK
from uwgen.runtime.wire.codec import DecodeError, load_items
from uwgen.security import wire
from uwgen.security.droplog import SUMMARY_PERIOD
from uwgen.runtime.delivery.epoch import on_schedule
from uwgen.security.epochs import EPOCH_NUMBERS
from uwgen.security.errors import SecurityError
from uwgen.security.files import SideLock
from uwgen.security.side import (DROP_REASONS, SYNC_EVERY, SYNC_FIRST, SYNC_PERIOD,  # noqa: F401 (re-exported)
                                 GuardConfig, SideSeal)
from uwgen.runtime.delivery.freshness import stamp
from uwgen.security.keys import new_epoch
from uwgen.security.receiver import Numbering
from uwgen.security.window import WINDOW

COUNTERS = ("protected", "sync_sent", "verified", "epochs_seen", "protect_failed", *DROP_REASONS)


class LinkGuard(SideSeal):
    COUNTERS = COUNTERS

    def __init__(self, master: bytes, config: GuardConfig, *, clock: Clock = SYSTEM_CLOCK,
                 wall: Clock = WALL_CLOCK, name: str = "link", window: int = WINDOW,
                 lock: SideLock | None = None, epoch_source=new_epoch,
                 epoch_numbers: int = EPOCH_NUMBERS, summary_period: float = SUMMARY_PERIOD):
        if config.tag_bytes != wire.TAG_BYTES:
            raise SecurityError(f"the per-payload seal of wire format 1 has an {wire.TAG_BYTES}-byte "
                                f"tag, not {config.tag_bytes} (tag_bytes is for envelope links, wire format 4)")
        super().__init__(master, config, clock=clock, wall=wall, name=name, window=window,
                         lock=lock, epoch_source=epoch_source, epoch_numbers=epoch_numbers,
                         summary_period=summary_period)

    def _max_age(self, ident: int) -> float:
        return self.config.max_ages.get(ident, self.config.max_age)

    # -- sending -----------------------------------------------------------------------

    def overhead(self, ident: int) -> int:
        """The most bytes protection adds to a payload of channel `ident` (0 when unprotected).
        A channel key above 255 (an action's feedback channel, 256 + id) carries wire id
        `ident & 0xFF`: counted as that id (at worst an over-estimate)."""
        modes = self.config.modes
        return wire.SYNC_OVERHEAD if ident in modes or (ident & 0xFF) in modes else 0

    def protect(self, ident: int, payload: bytes) -> bytes:
        """The payload as it goes on the wire, sealed now. The mode is that of the id in the
        payload's header, as the receiver reads it (`ident` is the link channel's key, which
        is not the wire id on an action's feedback channel)."""
        try:
            ident = wire.header_length(payload)[1]
        except wire.MalformedError:
            pass                                 # not a header: the channel's key decides
        mode = self.config.modes.get(ident)
        if mode is None:
            return payload
        with self._lock:
            seq = self.session.take()
            now = self.clock.now()
            sync = on_schedule(seq, now, self._last_sync) or self._sync_due > 0
            self._sync_due = max(0, self._sync_due - 1)
            self.counters.inc("protected")
            word = None
            if sync:
                self._last_sync = now
                self.counters.inc("sync_sent")
                word = wire.Sync(self.session.epoch, stamp(self.wall.now()))
            aead = self.session.aead
        return wire.seal(aead, mode, self.config.sender, seq, payload,
                         self.config.fingerprints.get(ident, b""), word)

    # -- receiving ---------------------------------------------------------------------

    def unprotect(self, payload: bytes) -> bytes | None:
        """The unprotected payload, or None when it is dropped (counted by reason)."""
        try:
            _, ident, _ = wire.header_length(payload)
        except wire.MalformedError:
            with self._lock:                    # garbage: no id, so nothing may pass
                return self.drops.drop("malformed", 0)
        mode = self.config.modes.get(ident)
        if mode is None:
            return payload
        with self._lock:
            return self._check(payload, ident, mode)

    def _check(self, payload: bytes, ident: int, mode: str) -> bytes | None:
        drop = self.drops.drop
        try:
            p = wire.parse(payload)
        except wire.MalformedError:
            return drop("unprotected" if _plain(payload) else "truncated", ident)
        if p.sender == self.config.sender:
            return drop("reflected", ident, p.sender)
        if p.sender not in self.config.peers:
            return drop("unprotected" if _plain(payload) else "unknown_sender", ident, p.sender)
        fp = self.config.fingerprints.get(ident, b"")
        numbering = Numbering(p.sender, p.partial, wire.PARTIAL_BITS, p.full_seq(), p.sync)
        got = self.receiver.admit(numbering, self._max_age(ident),
                                  lambda aead, seq: _open(aead, mode, p, seq, fp))
        if isinstance(got, str):
            reason = "unprotected" if got == "bad_tag" and _plain(payload) else got
            return drop(reason, ident, p.sender)
        self.counters.inc("verified")
        return got

    # -- accounting and shutdown -------------------------------------------------------

    def stats(self) -> dict:
        return self._side_stats()


def _open(aead, mode: str, p: wire.Parsed, seq: int, fingerprint: bytes) -> bytes | None:
    try:
        return wire.open_parsed(aead, mode, p, seq, fingerprint)
    except wire.InvalidTag:
        return None


def _plain(payload: bytes) -> bool:
    """Whether the whole payload reads as an ordinary (unprotected) CBOR sequence."""
    try:
        load_items(payload)
        return True
    except DecodeError:
        return False
