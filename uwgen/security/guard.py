"""LinkGuard: what a link calls to protect outgoing payloads and check incoming ones.

`protect(id, payload)` is called when a whole payload leaves its queue (before it is
fragmented), so sequence numbers are spent only on payloads that are sent and the gaps a
receiver sees stay small. `unprotect(payload)` is called on every whole payload after
reassembly: for an id whose mode is sign or encrypt it returns the unprotected payload
only when the tag is good and the number is new to the sender's replay window; every
other frame for such an id is dropped and counted by reason. Payloads of unprotected or
unknown ids pass unchanged (the bridge routes and counts them as before); a payload
without a readable header is dropped (`malformed`).

Logs: the first drop of each reason is logged with its detail, later ones only counted,
plus one summary line per `summary_period` (injected clock) while drops go on, so a
forger cannot flood the log.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.codec import DecodeError, load_items
from uwgen.runtime.stats import Counters
from uwgen.security import wire
from uwgen.security.errors import SecurityError
from uwgen.security.keys import key_id, sender_key
from uwgen.security.state import RECV_BLOCK, SEND_BLOCK, SequenceSource, State, StateFile
from uwgen.security.window import MAX_JUMP, NEW, WINDOW, ReplayWindow

log = logging.getLogger("uwgen.security")

DROP_REASONS = ("bad_tag", "replay", "too_old", "too_far", "unknown_sender", "reflected", "unsynced",
                "unprotected", "truncated", "malformed", "state_error")
COUNTERS = ("protected", "sync_sent", "verified", "protect_failed", *DROP_REASONS)
SYNC_FIRST = 3          # the first frames after a start carry the full sequence number
SYNC_EVERY = 32         # then every frame whose number is a multiple of this,
SYNC_PERIOD = 30.0      # and the first frame after this many seconds without one
SUMMARY_PERIOD = 60.0   # seconds between summary lines while drops go on

WHY = {
    "bad_tag": "the tag does not verify (forged, corrupted, or another network's key)",
    "replay": "a number this sender already used (a replay)",
    "too_old": "a number older than the replay window (an old frame replayed, or a sender that "
               "lost its state file and started its numbers again: give the network a new key)",
    "too_far": f"a number more than {MAX_JUMP} above the highest one accepted from this sender "
               "(refused: one frame may not move the window that far)",
    "unknown_sender": "a sender id no side of the manifest has",
    "reflected": "this side's own sender id (a frame sent back to us)",
    "unsynced": "no sequence state for this sender yet; waiting for one of its sync frames",
    "unprotected": "not protected, but the manifest protects this id",
    "truncated": "too short to be a protected payload",
    "malformed": "no readable header (kind, id, seq)",
    "state_error": "the state file could not be written",
}


@dataclass(frozen=True)
class GuardConfig:
    network: str
    sender: int                                    # this side's sender id
    peers: dict[int, str]                          # other sides: sender id -> side name
    modes: dict[int, str]                          # protected ids -> sign | encrypt
    fingerprints: dict[int, bytes] = field(default_factory=dict)


class LinkGuard:
    def __init__(self, master: bytes, config: GuardConfig, store: StateFile, *,
                 clock: Clock = SYSTEM_CLOCK, name: str = "link", window: int = WINDOW,
                 send_block: int = SEND_BLOCK, recv_block: int = RECV_BLOCK,
                 summary_period: float = SUMMARY_PERIOD):
        if config.sender in config.peers:
            raise SecurityError(f"sender id {config.sender} is given to two sides")
        for ident, mode in config.modes.items():
            if mode not in (wire.SIGN, wire.ENCRYPT):
                raise SecurityError(f"id {ident}: mode {mode!r} is not sign or encrypt")
        self.config, self.store, self.clock, self.name = config, store, clock, name
        self.counters = Counters(COUNTERS)
        store.lock()                  # a second copy of this side is refused here
        try:
            self.state: State = store.load()
        except BaseException:
            store.unlock()
            raise
        self._aead = {s: wire.new_aead(sender_key(master, config.network, s))
                      for s in (config.sender, *config.peers)}
        self._lock = threading.Lock()
        self._seqs = SequenceSource(store, self.state, send_block)
        self._sent = 0
        self._last_sync = float("-inf")
        self._recv_block = recv_block
        self._windows = {s: ReplayWindow.from_floor(f, window)
                         for s, f in self.state.floors.items() if s in config.peers}
        self._window_size = window
        self._logged: set[str] = set()
        self._summary_period = summary_period
        self._summary_at = clock.now() + summary_period
        self._since_summary: dict[str, int] = {}

    @classmethod
    def for_key(cls, master: bytes, config: GuardConfig, state_path, io=None, **kw) -> "LinkGuard":
        return cls(master, config,
                   StateFile(state_path, key_id(master, config.network), io, sender=config.sender), **kw)

    # -- sending -----------------------------------------------------------------------

    def overhead(self, ident: int) -> int:
        """The most bytes protection adds to a payload of channel `ident` (0 when unprotected).
        A channel key above 255 (an action's feedback channel, 256 + id) carries wire id
        `ident & 0xFF`: counted as that id (at worst an over-estimate)."""
        modes = self.config.modes
        return wire.SYNC_OVERHEAD if ident in modes or (ident & 0xFF) in modes else 0

    def protect(self, ident: int, payload: bytes) -> bytes:
        """The payload as it goes on the wire; SecurityError (counted) if no number can be
        reserved: nothing unprotected ever leaves for a protected id. The mode is that of the
        id in the payload's header, as the receiver reads it (`ident` is the link channel's
        key, which is not the wire id on an action's feedback channel)."""
        try:
            ident = wire.header_length(payload)[1]
        except wire.MalformedError:
            pass                                 # not a header: the channel's key decides
        mode = self.config.modes.get(ident)
        if mode is None:
            return payload
        with self._lock:
            try:
                seq = self._seqs.take()
            except SecurityError as exc:
                self.counters.inc("protect_failed")
                if "protect_failed" not in self._logged:
                    self._logged.add("protect_failed")
                    log.error("[%s] not sending: %s (further failures are counted)", self.name, exc)
                raise
            now = self.clock.now()
            sync = (self._sent < SYNC_FIRST or seq % SYNC_EVERY == 0
                    or now - self._last_sync >= SYNC_PERIOD)
            self._sent += 1
            self.counters.inc("protected")
            if sync:
                self._last_sync = now
                self.counters.inc("sync_sent")
        return wire.seal(self._aead[self.config.sender], mode, self.config.sender, seq, payload,
                         self.config.fingerprints.get(ident, b""), sync)

    # -- receiving ---------------------------------------------------------------------

    def unprotect(self, payload: bytes) -> bytes | None:
        """The unprotected payload, or None when it is dropped (counted by reason)."""
        try:
            _, ident, _ = wire.header_length(payload)
        except wire.MalformedError:
            with self._lock:                    # garbage: no id, so nothing may pass
                return self._drop("malformed", 0)
        mode = self.config.modes.get(ident)
        if mode is None:
            return payload
        with self._lock:
            return self._check(payload, ident, mode)

    def _check(self, payload: bytes, ident: int, mode: str) -> bytes | None:
        try:
            p = wire.parse(payload)
        except wire.MalformedError:
            return self._drop("unprotected" if _plain(payload) else "truncated", ident)
        if p.sender == self.config.sender:
            return self._drop("reflected", ident, p.sender)
        if p.sender not in self.config.peers:
            return self._drop("unprotected" if _plain(payload) else "unknown_sender", ident, p.sender)
        window = self._windows.get(p.sender)
        seq = p.full_seq()
        if seq is None:
            seq = window.reconstruct(p.partial) if window is not None else None
            if seq is None:
                return self._drop("unsynced", ident, p.sender)
        try:
            plain = wire.open_parsed(self._aead[p.sender], mode, p, seq,
                                     self.config.fingerprints.get(ident, b""))
        except wire.InvalidTag:
            return self._drop("unprotected" if _plain(payload) else "bad_tag", ident, p.sender)
        if window is None:
            window = self._windows[p.sender] = ReplayWindow(self._window_size)
        verdict = window.check(seq)
        if verdict != NEW:
            return self._drop(verdict, ident, p.sender)
        floor = self.state.floors.get(p.sender)
        if floor is None or seq > floor:
            self.state.floors[p.sender] = min(seq + self._recv_block, wire.MAX_SEQ)
            try:
                self.store.save(self.state)
            except SecurityError as exc:
                if floor is None:
                    del self.state.floors[p.sender]
                else:
                    self.state.floors[p.sender] = floor
                log.error("[%s] %s", self.name, exc)
                return self._drop("state_error", ident, p.sender)
        window.accept(seq)
        self.counters.inc("verified")
        return plain

    def _drop(self, reason: str, ident: int, sender: int | None = None) -> None:
        self.counters.inc(reason)
        self._since_summary[reason] = self._since_summary.get(reason, 0) + 1
        if reason not in self._logged:
            self._logged.add(reason)
            who = "" if sender is None else f" from sender {sender}"
            log.warning("[%s] dropped a payload for id %d%s: %s (first of its kind; further ones "
                        "are counted in the status and summed up every %g s)",
                        self.name, ident, who, WHY[reason], self._summary_period)
        now = self.clock.now()
        if now >= self._summary_at:
            self._summary()
            self._summary_at = now + self._summary_period
        return None

    def _summary(self) -> None:
        if self._since_summary:
            parts = ", ".join(f"{k} {v}" for k, v in sorted(self._since_summary.items()))
            log.warning("[%s] security drops since last summary: %s", self.name, parts)
            self._since_summary.clear()

    # -- accounting and shutdown -------------------------------------------------------

    def stats(self) -> dict:
        c = self.counters.as_dict()
        return {**c, "dropped": sum(c[r] for r in DROP_REASONS),
                "sender": self.config.sender, "next_seq": self._seqs.next,
                "reserved": self.state.reserved,
                "peers": {str(s): {"side": self.config.peers[s], "high": w.high}
                          for s, w in sorted(self._windows.items())}}

    def close(self) -> None:
        """Write the exact numbers (a clean restart then skips nothing) and the last summary."""
        with self._lock:
            self._summary()
            self.state.reserved = self._seqs.next
            for s, w in self._windows.items():
                if w.high is not None:
                    self.state.floors[s] = w.high
            try:
                self.store.save(self.state)
            except SecurityError as exc:
                log.error("[%s] %s (the next start skips the reserved numbers)", self.name, exc)
            self.store.unlock()


def _plain(payload: bytes) -> bool:
    """Whether the whole payload reads as an ordinary (unprotected) CBOR sequence."""
    try:
        load_items(payload)
        return True
    except DecodeError:
        return False
