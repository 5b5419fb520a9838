"""Counted drops with throttled logs: the first drop of each reason is logged with its detail,
later ones only counted, plus one summary line per `summary_period` (injected clock) while
drops go on, so a forger cannot flood the log."""
from __future__ import annotations

import logging

from uwgen.runtime.clock import Clock
from uwgen.runtime.stats import Counters
from uwgen.security.window import MAX_JUMP

log = logging.getLogger("uwgen.security")

SUMMARY_PERIOD = 60.0   # seconds between summary lines while drops go on

WHY = {
    "bad_tag": "the tag does not verify (forged, corrupted, another network's key, or a sender "
               "whose epoch this side has not heard yet: it catches up at the sender's next sync)",
    "replay": "a number this sender already used in this epoch (a replay)",
    "too_old": "a number older than the replay window (an old frame replayed)",
    "too_far": f"a number more than {MAX_JUMP} above the highest one accepted from this sender "
               "(refused: one frame may not move the window that far)",
    "stale": "older than its entry's max age (a recorded or held-back frame), or stamped by a "
             "clock further from ours than the tolerance",
    "before_start": "a sync frame of a new epoch sealed before this side started (recorded and "
                    "replayed, or still on its way at the start: taken from the sender's next one)",
    "unknown_sender": "a sender id no side of the manifest has",
    "reflected": "this side's own sender id (a frame sent back to us)",
    "unsynced": "no epoch of this sender yet; waiting for one of its sync frames",
    "unprotected": "not protected, but the manifest protects this id (an envelope link: a packet "
                   "without a tag on a secured link)",
    "truncated": "too short to be a protected payload",
    "malformed": "no readable header (kind, id, seq), or a sync part (K) without its time (T)",
    "tag_length": "a sync packet whose tag verifies only at another length than this side's "
                  "(security tag_bytes): the sender was built from a manifest with another "
                  "tag_bytes; rebuild both sides from one manifest",
}


class DropLog:
    def __init__(self, counters: Counters, clock: Clock, name: str,
                 summary_period: float = SUMMARY_PERIOD):
        self.counters, self.clock, self.name = counters, clock, name
        self._period = summary_period
        self._logged: set[str] = set()
        self._at = clock.now() + summary_period
        self._since: dict[str, int] = {}

    def drop(self, reason: str, ident: int | None, sender: int | None = None) -> None:
        """Count (and maybe log) one dropped payload (a packet when `ident` is None); returns
        None for `return drop(...)`."""
        self.counters.inc(reason)
        self._since[reason] = self._since.get(reason, 0) + 1
        if reason not in self._logged:
            self._logged.add(reason)
            who = "" if sender is None else f" from sender {sender}"
            what = "a packet" if ident is None else f"a payload for id {ident}"
            log.warning("[%s] dropped %s%s: %s (first of its kind; further ones "
                        "are counted in the status and summed up every %g s)",
                        self.name, what, who, WHY[reason], self._period)
        now = self.clock.now()
        if now >= self._at:
            self.summary()
            self._at = now + self._period
        return None

    def summary(self) -> None:
        if self._since:
            parts = ", ".join(f"{k} {v}" for k, v in sorted(self._since.items()))
            log.warning("[%s] security drops since last summary: %s", self.name, parts)
            self._since.clear()
