"""Reassembly of fragments (docs/wire-format.md sections 7 and 11): the receiver's side of
uwgen.runtime.wire.fragment.

`Reassembler.feed(payload)` takes every payload received; a fragment is held with the others of
its transfer until the message can be rebuilt (from its data chunks, or from any k of its data
and repair fragments), then the whole payload is returned. Memory is bounded (`max_transfers`,
`max_bytes`), a transfer not completed within `timeout` is dropped, and every fragment that
cannot belong is counted, never raised.
"""
from __future__ import annotations

import logging
import zlib
from collections import deque
from dataclasses import dataclass, field

from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.stats import Counters, log_count
from uwgen.runtime.wire import fec
from uwgen.runtime.wire.fragment import Fragment, FragmentError, parse_any, read_head
from uwgen.runtime.wire.framing import MAX_PAYLOAD

log = logging.getLogger("uwgen.link.fragment")


# -- receiver ----------------------------------------------------------------------------------

@dataclass
class _Partial:
    """The fragments held for one transfer, and the rules they must agree on."""

    count: int                                                  # data fragments (k)
    chunks: dict[int, bytes] = field(default_factory=dict)      # data, by index
    repairs: dict[int, bytes] = field(default_factory=dict)     # repair blocks, by index (>= count)
    message_size: int | None = None                             # known from any repair fragment
    size: int = 0                                               # bytes held
    last_seen: float = 0.0

    @property
    def held(self) -> int:
        return len(self.chunks) + len(self.repairs)

    def conflict(self, f: Fragment) -> str | None:
        """Why `f` cannot belong with these fragments ("duplicate" if it is one already held)."""
        if f.count != self.count:
            return f"count {f.count} after {self.count}"
        held = (self.repairs if f.is_repair else self.chunks).get(f.index)
        if held is not None:
            return "duplicate" if held == f.chunk else f"other bytes for fragment {f.index}"
        if f.is_repair and self.message_size is not None and f.size != self.message_size:
            return f"message size {f.size} after {self.message_size}"
        # Chunks 0..count-2 and every repair block share one length; the last chunk is no longer,
        # and exactly message_size - (count - 1) * that length when the size is known.
        full = {len(c) for i, c in self.chunks.items() if i < self.count - 1}
        full |= {len(c) for c in self.repairs.values()}
        last = self.chunks.get(self.count - 1)
        size = f.size if f.is_repair else self.message_size
        if f.is_repair or f.index < self.count - 1:
            if full and len(f.chunk) not in full:
                return f"chunk length {len(f.chunk)}, others {min(full)}"
            if last is not None and len(last) > len(f.chunk):
                return f"chunk length {len(f.chunk)} shorter than the last chunk"
            if f.is_repair and last is not None and len(last) != size - (self.count - 1) * len(f.chunk):
                return f"message size {size} disagrees with the last chunk"
        else:
            if full and len(f.chunk) > min(full):
                return f"last chunk of {len(f.chunk)} bytes longer than the others"
            if size is not None and full and len(f.chunk) != size - (self.count - 1) * min(full):
                return f"last chunk of {len(f.chunk)} bytes disagrees with message size {size}"
        return None

    def add(self, f: Fragment) -> None:
        if f.is_repair:
            self.repairs[f.index] = f.chunk
            self.message_size = f.size
        else:
            self.chunks[f.index] = f.chunk
        self.size += len(f.chunk)

    def message(self) -> tuple[bytes, bool] | None:
        """(the whole message, whether repair blocks were needed), once enough fragments are held."""
        if len(self.chunks) == self.count:
            return b"".join(self.chunks[i] for i in range(self.count)), False
        if self.message_size is None or self.held < self.count:
            return None
        width = len(next(iter(self.repairs.values())))
        blocks = {i: c.ljust(width, b"\0") for i, c in self.chunks.items()}
        blocks.update(self.repairs)
        data = fec.rebuild(self.count, max(self.repairs) - self.count + 1, blocks)
        return b"".join(data)[:self.message_size], True


REASSEMBLER_COUNTERS = (
    "fragments",      # fragment payloads received
    "completed",      # messages reassembled and delivered
    "malformed",      # not a well-formed fragment
    "inconsistent",   # disagreed with the fragments already held for its transfer (partial dropped)
    "duplicate",      # a fragment already held, or of a message already delivered
    "rebuilt",        # messages completed with the help of repair fragments (also in completed)
    "surplus_repair", # repair fragments of a message already delivered (not needed: no loss)
    "timed_out",      # partial messages dropped because a fragment never came
    "evicted",        # partial messages dropped to stay within the memory bounds
    "oversized",      # messages that could never fit the memory bound
)


class Reassembler:
    """Rebuilds fragmented payloads; bounded memory; drops (and counts) what cannot complete.

    - at most `max_transfers` partial messages and `max_bytes` of chunks are held; making room
      evicts the partial message that has waited longest since its last fragment;
    - a partial message that received no fragment for `timeout` seconds is dropped (a fragment was
      lost on the link);
    - a fragment that contradicts the ones held for its transfer (other count, other bytes at the
      same index, chunk sizes that cannot come from one message) drops the old partial message and
      starts over with the new fragment: a restarted sender reusing the number wins;
    - a message is delivered at most once: a repeat of a just-delivered message (same transfer,
      count and content, within `timeout`) is dropped as duplicate.
    """

    def __init__(self, fragment_id: int, clock: Clock = SYSTEM_CLOCK, *, timeout: float = 30.0,
                 max_transfers: int = 8, max_bytes: int = 256 * 1024, name: str = "link"):
        if timeout <= 0 or max_transfers < 1 or max_bytes < MAX_PAYLOAD:
            raise ValueError("Reassembler needs timeout > 0, max_transfers >= 1, max_bytes >= 255")
        self.fragment_id = fragment_id
        self.clock = clock
        self.timeout = timeout
        self.max_transfers = max_transfers
        self.max_bytes = max_bytes
        self.name = name
        self.stats = Counters(REASSEMBLER_COUNTERS)
        self._partial: dict[int, _Partial] = {}
        self._bytes = 0
        self.lost_by_id: dict[int, int] = {}     # messages lost on the link, by their topic/service id
        self.lost_unattributed = 0               # ... whose fragment 0 never came
        self._recent: deque[tuple[float, int, int, int]] = deque(maxlen=16)  # (time, transfer, count, crc)

    @property
    def pending(self) -> int:
        """Partial messages held."""
        return len(self._partial)

    @property
    def buffered_bytes(self) -> int:
        return self._bytes

    def feed(self, payload: bytes) -> bytes | None:
        """Take one fragment payload; return the whole message when this fragment completes it."""
        now = self.clock.now()
        self.expire(now)
        self.stats.inc("fragments")
        try:
            f = parse_any(payload, self.fragment_id)
        except FragmentError as e:
            log_count(log, logging.WARNING, self.stats.inc("malformed"), "[%s] dropped %s", self.name, e)
            return None

        p = self._partial.get(f.transfer)
        if p is None and f.is_repair and self._just_delivered(f, now):
            self.stats.inc("surplus_repair")      # its message came whole: nothing was lost
            return None
        if p is not None:
            problem = p.conflict(f)
            if problem == "duplicate":
                self.stats.inc("duplicate")
                p.last_seen = now
                return None
            if problem:
                log_count(log, logging.WARNING, self.stats.inc("inconsistent"),
                          "[%s] transfer %d: %s; dropped its %d fragments", self.name, f.transfer, problem,
                          p.held)
                self._lose(f.transfer)
                p = None
        if (f.is_repair or f.index < f.count - 1) and f.count * len(f.chunk) > self.max_bytes:
            # Every chunk but the last has this length: the whole message can never be held.
            log_count(log, logging.WARNING, self.stats.inc("oversized"),
                      "[%s] transfer %d: %d fragments of %d bytes exceed the %d-byte reassembly bound",
                      self.name, f.transfer, f.count, len(f.chunk), self.max_bytes)
            if p is not None:
                self._lose(f.transfer)
            return None
        if p is None:
            p = _Partial(count=f.count)
            self._make_room(len(f.chunk), new_transfer=True)
            self._partial[f.transfer] = p
        else:
            self._make_room(len(f.chunk), new_transfer=False, keep=f.transfer)
        p.add(f)
        p.last_seen = now
        self._bytes += len(f.chunk)
        done = p.message()
        if done is None:
            return None

        self._drop(f.transfer)
        message, rebuilt = done
        key = (f.transfer, p.count, zlib.crc32(message))
        if any(r[1:] == key and now - r[0] <= self.timeout for r in self._recent):
            self.stats.inc("duplicate")
            return None
        self._recent.append((now, *key))
        self.stats.inc("completed")
        if rebuilt:
            self.stats.inc("rebuilt")
        return message

    def expire(self, now: float | None = None) -> int:
        """Drop partial messages that waited `timeout` since their last fragment; return how many."""
        now = self.clock.now() if now is None else now
        old = [t for t, p in self._partial.items() if now - p.last_seen >= self.timeout]
        for t in old:
            p = self._partial[t]
            log_count(log, logging.WARNING, self.stats.inc("timed_out"),
                      "[%s] transfer %d: %d of %d fragments after %.1f s; dropped (a fragment was lost)",
                      self.name, t, p.held, p.count, self.timeout)
            self._lose(t)
        return len(old)

    # -- internals -----------------------------------------------------------------------------

    def _just_delivered(self, f: Fragment, now: float) -> bool:
        return any(r[1] == f.transfer and r[2] == f.count and now - r[0] <= self.timeout for r in self._recent)

    def _drop(self, transfer: int) -> None:
        p = self._partial.pop(transfer)
        self._bytes -= p.size

    def _lose(self, transfer: int) -> None:
        """Drop a partial message that will never complete, and say whose message it was: chunk 0
        starts with the payload's own kind and id (unknown when chunk 0 never came)."""
        chunk0 = self._partial[transfer].chunks.get(0)
        self._drop(transfer)
        try:
            _, pos = read_head(chunk0 or b"", 0, 0, "kind")
            ident, _ = read_head(chunk0 or b"", pos, 0, "id")
        except FragmentError:
            self.lost_unattributed += 1
            return
        self.lost_by_id[ident] = self.lost_by_id.get(ident, 0) + 1

    def _make_room(self, size: int, new_transfer: bool, keep: int | None = None) -> None:
        while self._partial and (
                self._bytes + size > self.max_bytes
                or (new_transfer and len(self._partial) >= self.max_transfers)):
            victims = [t for t in self._partial if t != keep]
            if not victims:
                break
            oldest = min(victims, key=lambda t: self._partial[t].last_seen)
            p = self._partial[oldest]
            log_count(log, logging.WARNING, self.stats.inc("evicted"),
                      "[%s] transfer %d: %d of %d fragments evicted to bound reassembly memory",
                      self.name, oldest, p.held, p.count)
            self._lose(oldest)
