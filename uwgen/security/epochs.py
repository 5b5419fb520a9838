"""Epochs: the sender's fresh session per start, and what a receiver keeps per sender.

A sender picks a random 6-byte epoch when it starts (and again every `EPOCH_NUMBERS`
numbers), seals under that epoch's working key (`keys.working_key`) and counts its numbers
from 0 in memory. Nothing is read from or written to disk: a restart, a restored disk image,
a second copy of the side, a renumbered id, all pick another epoch and so another key, and a
(key, nonce) pair never repeats (two epochs collide with probability 2^-48 per pair of starts).

A receiver keeps, per sender, the last `KEEP` epochs it accepted, each with its working key
and its replay window; a frame without a sync word is tried under the most recent first. It
also keeps the last `RETIRED` epochs it let go, with their windows: a sync frame of one is
taken back under its old window (so nothing seen before is taken again: a recorded sync frame
of an epoch pushed out is a replay, never a new epoch), so two fresh epochs sent by a key
holder cannot push the real sender's epoch out for good (docs/security.md, "What a key holder
can do to availability").
Pure classes: the random source and the key derivation are passed in.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uwgen.security.window import MAX_JUMP, ReplayWindow

EPOCH_NUMBERS = MAX_JUMP      # a sender starts a new epoch after this many numbers
KEEP = 2                      # epochs a receiver remembers per sender
RETIRED = 64                  # epochs it remembers it let go (to refuse them), per sender


class SendSession:
    """This side's epoch and next number."""

    def __init__(self, aead_for: Callable[[bytes], Any], new_epoch: Callable[[], bytes],
                 limit: int = EPOCH_NUMBERS):
        self._aead_for, self._new_epoch, self.limit = aead_for, new_epoch, limit
        self.epochs_started = 0
        self._start()

    def _start(self) -> None:
        self.epoch = self._new_epoch()
        self.aead = self._aead_for(self.epoch)
        self.next = 0
        self.epochs_started += 1

    def take(self) -> int:
        """The next number of the current epoch (a new epoch once this one is used up)."""
        if self.next >= self.limit:
            self._start()
        seq = self.next
        self.next += 1
        return seq


@dataclass
class PeerEpoch:
    epoch: bytes
    aead: Any
    window: ReplayWindow
    shadow: ReplayWindow | None = None   # the window before a jump (receiver.py)


class PeerEpochs:
    """The epochs of one sender that a receiver accepted, most recent first."""

    def __init__(self, keep: int = KEEP, retired: int = RETIRED):
        self.keep = keep
        self._epochs: list[PeerEpoch] = []
        self._retired: OrderedDict[bytes, PeerEpoch] = OrderedDict()
        self._retire_limit = retired

    def retired(self, epoch: bytes) -> PeerEpoch | None:
        """The epoch as it was let go (its window too), when it was accepted once and let go
        since: taken back only under that window."""
        return self._retired.get(epoch)

    def get(self, epoch: bytes) -> PeerEpoch | None:
        return next((e for e in self._epochs if e.epoch == epoch), None)

    def recent(self) -> list[PeerEpoch]:
        return list(self._epochs)

    def touch(self, entry: PeerEpoch) -> None:
        """`entry` accepted a frame: it becomes the most recent (the oldest beyond `keep` go)."""
        if entry in self._epochs:
            self._epochs.remove(entry)
        self._retired.pop(entry.epoch, None)
        self._epochs.insert(0, entry)
        for old in self._epochs[self.keep:]:
            self._retired[old.epoch] = old
        del self._epochs[self.keep:]
        while len(self._retired) > self._retire_limit:
            self._retired.popitem(last=False)

    @property
    def current(self) -> PeerEpoch | None:
        return self._epochs[0] if self._epochs else None
