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

from uwgen.runtime.wire import envelope as env

SYNC_FIRST = 3            # the first packets of an epoch carry K (as the seal's)
SYNC_EVERY = 64           # then 1 in this many
SYNC_PERIOD = 30.0        # and after this many seconds without
SYNC_ANSWER = 2           # packets carrying K after a peer's new epoch
UNTIL_ACKED = 16          # K on every packet until one is acknowledged, at most this many
SYNC_BYTES = env.SYNC_LEN + env.TIME_LEN


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
        self._planned = (seq < SYNC_FIRST or seq % SYNC_EVERY == 0 or self._answer > 0
                         or now - self._last_sync >= SYNC_PERIOD
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
