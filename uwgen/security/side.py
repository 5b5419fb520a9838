"""What both seals of a side share: the per-payload `LinkGuard` (wire format 1) and the
per-packet `PacketSeal` (wire format 2) check the same configuration, hold the same side lock,
derive working keys from the same master key and epoch (`_aead`), send under one
`SendSession`, admit peers' epochs through one `Receiver`, count drops in one `DropLog`, and
report and close alike. Each subclass adds how it seals and opens."""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path

from uwgen.manifest.model import DEFAULT_TAG_BYTES, TAG_BYTES
from uwgen.runtime.clock import Clock
from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE, MAX_AGE, Freshness
from uwgen.runtime.stats import Counters
from uwgen.security import wire
from uwgen.security.droplog import DropLog
from uwgen.security.epochs import SendSession
from uwgen.security.errors import SecurityError
from uwgen.security.files import SideLock
from uwgen.security.keys import working_key
from uwgen.security.receiver import Receiver

DROP_REASONS = ("bad_tag", "replay", "too_old", "too_far", "stale", "before_start", "unknown_sender",
                "reflected", "unsynced", "unprotected", "truncated", "malformed", "tag_length")
# When the sync word (K) goes: one schedule for every link, sealed or not (docs/seams.md
# sections 2 and 8), kept with the unsealed links' epochs below the security layer.
from uwgen.runtime.delivery.epoch import SYNC_EVERY, SYNC_FIRST, SYNC_PERIOD  # noqa: E402,F401


@dataclass(frozen=True)
class GuardConfig:
    network: str
    sender: int                                    # this side's sender id
    peers: dict[int, str]                          # other sides: sender id -> side name
    modes: dict[int, str]                          # protected ids -> sign | encrypt
    fingerprints: dict[int, bytes] = field(default_factory=dict)
    max_ages: dict[int, float] = field(default_factory=dict)   # id -> seconds (its ttl)
    max_age: float = MAX_AGE                       # ids without one
    clock_tolerance: float = CLOCK_TOLERANCE
    tag_bytes: int = DEFAULT_TAG_BYTES             # AES-CCM tag length (4, 6, 8; per packet on wire format 2)


class SideSeal:
    COUNTERS: tuple[str, ...] = ()

    def __init__(self, master: bytes, config: GuardConfig, *, clock: Clock, wall: Clock,
                 name: str, window: int, lock: SideLock | None, epoch_source, epoch_numbers: int,
                 summary_period: float, reentrant: bool = False):
        if config.sender in config.peers:
            raise SecurityError(f"sender id {config.sender} is given to two sides")
        if config.tag_bytes not in TAG_BYTES:
            raise SecurityError(f"a tag of {config.tag_bytes} bytes: 4, 6 or 8 are allowed")
        for ident, mode in config.modes.items():
            if mode not in (wire.SIGN, wire.ENCRYPT):
                raise SecurityError(f"id {ident}: mode {mode!r} is not sign or encrypt")
        self.config, self.clock, self.wall, self.name = config, clock, wall, name
        self._master = master
        self.counters = Counters(self.COUNTERS)
        self.drops = DropLog(self.counters, clock, name, summary_period)
        self.freshness = Freshness(config.clock_tolerance)
        self._lock_file = lock.acquire() if lock is not None else None   # one copy per side
        self._lock = threading.RLock() if reentrant else threading.Lock()
        self.session = SendSession(lambda e: self._aead(config.sender, e), epoch_source,
                                   epoch_numbers)
        self._last_sync = float("-inf")
        self._sync_due = 0                      # sync frames owed to a peer that (re)started
        self.receiver = Receiver(config.peers, self._aead, self.freshness, clock, wall, window,
                                 on_new_epoch=self._peer_restarted)

    @classmethod
    def for_key(cls, master: bytes, config: GuardConfig, lock_path: Path | None = None, **kw):
        """A seal holding `lock_path` (if given) while it runs: a second copy is refused."""
        lock = (SideLock(lock_path, f"side {config.sender} of network {config.network!r}")
                if lock_path is not None else None)
        return cls(master, config, lock=lock, **kw)

    @property
    def lock_path(self) -> Path | None:
        return self._lock_file.path if self._lock_file is not None else None

    def _aead(self, sender: int, epoch: bytes):
        return wire.new_aead(working_key(self._master, self.config.network, sender, epoch),
                             self.config.tag_bytes)

    def _peer_restarted(self, sender: int) -> None:
        """A peer's new epoch: it may not know ours either, so the next frames carry it."""
        self.counters.inc("epochs_seen")
        self._sync_due = max(self._sync_due, SYNC_FIRST)

    def _side_stats(self) -> dict:
        """Counters, drops, this side's epoch and each peer's current epoch (under the lock)."""
        c = self.counters.as_dict()
        peers = {}
        for s in sorted(self.config.peers):
            pe = self.receiver.peer(s)
            if pe.current is not None:
                peers[str(s)] = {"side": self.config.peers[s], "epoch": pe.current.epoch.hex(),
                                 "high": pe.current.window.high}
        return {**c, "dropped": sum(c[r] for r in DROP_REASONS), "sender": self.config.sender,
                "epoch": self.session.epoch.hex(), "next_seq": self.session.next, "peers": peers}

    def close(self) -> None:
        """The last summary line; lets another copy of this side start."""
        with self._lock:
            self.drops.summary()
            if self._lock_file is not None:
                self._lock_file.release()
