"""The sender's epoch on an unsealed wire-format-2 link (docs/seams.md sections 2 and 8).

Every wire-format-2 link, sealed or not, carries the sender's per-start epoch in K (6 random
bytes, new at every start, never stored, and the packet number's bits 12-43), so a receiver
keys what it knows of a sender by (sender, epoch) and a restarted sender's packets and
reliable messages are never taken as repeats of the ones before. On a sealed link K is the
seal's (`uwgen.security.packet_seal`); on an unsealed one this class gives it, on the seal's
schedule (the first `SYNC_FIRST` packets of an epoch, 1 in `SYNC_EVERY`, after `SYNC_PERIOD`
s without, and on the next `SYNC_ANSWER` packets after a peer's new epoch, so a peer that
restarted learns ours at once), and also on every packet until one of this epoch's packets is
acknowledged (at most `UNTIL_ACKED` packets: a one-way link never acknowledges), so losing
the first packets does not hide a restart. A packet carrying K carries T too. K is not
reserved in every packet (that would shrink every fragment by 10 bytes): it goes on the next
packet with room for it while due (`uwgen.runtime.delivery.reliability`). Pure: the caller
passes `now` and holds the lock.
"""
from __future__ import annotations

import os
from collections.abc import Callable

from typing import Any

from uwgen.runtime.delivery.reliable import RECEIVED_WINDOW, unwrap
from uwgen.runtime.wire import envelope as env

SYNC_FIRST = 3            # the first packets of an epoch carry K (as the seal's)
SYNC_EVERY = 64           # then 1 in this many
SYNC_PERIOD = 30.0        # and after this many seconds without
SYNC_ANSWER = 2           # packets carrying K after a peer's new epoch
UNTIL_ACKED = 16          # K on every packet until one is acknowledged, at most this many
SYNC_BYTES = env.SYNC_LEN + env.TIME_LEN


def on_schedule(seq: int, now: float, last_sync: float) -> bool:
    """K's standing schedule, the one rule for the seal and the unsealed link alike: the first
    `SYNC_FIRST` packets of an epoch, every `SYNC_EVERY`-th, and the first after `SYNC_PERIOD`
    s without one (`last_sync`: when K last went). The callers add their own occasions (a
    peer's new epoch or request, an unacknowledged start)."""
    return seq < SYNC_FIRST or seq % SYNC_EVERY == 0 or now - last_sync >= SYNC_PERIOD


def new_epoch() -> bytes:
    return os.urandom(env.EPOCH_LEN)


class SendEpoch:
    """This side's epoch and packet numbers on an unsealed link."""

    def __init__(self, source: Callable[[], bytes] = new_epoch):
        self.epoch = source()
        self.next = 0                      # the next packet's number (full)
        self._last_sync = -float("inf")
        self._answer = 0
        self.acked = False                 # a packet of this epoch was acknowledged
        self._planned: bool | None = None

    def due(self, now: float) -> bool:
        """Whether the next packet carries K (planned now, kept for it)."""
        seq = self.next
        self._planned = (on_schedule(seq, now, self._last_sync) or self._answer > 0
                         or (not self.acked and seq < UNTIL_ACKED))
        return self._planned

    def number(self) -> int:
        n = self.next
        self.next += 1
        return n

    def part(self, number: int, now: float) -> env.Sync | None:
        """K for packet `number` when it is due (as planned by `due`)."""
        due = self._planned if self._planned is not None else self.due(now)
        self._planned = None
        if not due:
            return None
        self._last_sync = now
        self._answer = max(0, self._answer - 1)
        return env.Sync(self.epoch, number >> 12)

    def peer_restarted(self) -> None:
        self._answer = SYNC_ANSWER


class PeerEpochs:
    """Each peer's epoch as this side receives it: K's when a packet has one; otherwise the
    last known, or a stand-in when none is known yet (named once K comes: the same start),
    or a new stand-in when its number fell behind the received window (a restarted sender
    whose packets with K were all lost)."""

    def __init__(self):
        self.known: dict[int, bytes] = {}
        self._restarts: dict[int, int] = {}

    def of(self, envelope: env.Envelope, receipts: dict[tuple[int, bytes], Any]
           ) -> tuple[bytes, bytes | None, bool]:
        """(epoch, the stand-in it renames or None, whether the peer restarted)."""
        peer = envelope.sender
        known = self.known.get(peer)
        if envelope.sync is not None:
            epoch = envelope.sync.epoch
            self.known[peer] = epoch
            if known is None or known == epoch:
                return epoch, None, False
            if len(known) != env.EPOCH_LEN:          # a stand-in: the same start, now named
                return epoch, known, False
            return epoch, None, True
        epoch = known if known is not None else b""
        r = receipts.get((peer, epoch))
        if r is not None and r.largest is not None and \
                unwrap(envelope.number, r.largest) < r.largest - RECEIVED_WINDOW:
            self._restarts[peer] = self._restarts.get(peer, 0) + 1
            self.known[peer] = b"restart %d" % self._restarts[peer]
            return self.known[peer], None, True
        self.known[peer] = epoch
        return epoch, None, False
