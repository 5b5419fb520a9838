"""Pacing writes to DESERT: never faster than the acoustic link can carry (sans-IO, clock-driven).

DESERT reads its socket in chunks of at most `max_read_length` bytes, turns each chunk into one
acoustic packet and sends one packet every `period`; its queue is unbounded. Two consequences:

- anything written faster than `max_read_length / period` waits in DESERT, beyond the reach of our
  policies, and latency grows without limit;
- the cost of a write is a *packet*, whatever its size: ten 6-byte writes are ten packets, while
  one 60-byte write is one.

So the pacer allows one write of at most `max_read_length` bytes per `period` (never two writes
less than a period apart), and the Outbox fills each write by *pulling* frames from the scheduler at
that moment. DESERT's queue then holds about one packet, i.e. one period of data; everything else
waits in the scheduler's queues.

Writes are packet-aligned: each write holds whole frames only, so each DESERT packet starts with a
frame and a lost packet costs exactly the frames in it (wire format, sections 1 and 11). A frame
that does not fit the room left waits, whole, for the next write (it goes before anything else), and the room left is filled
with the best frames of other channels that fit (`take(..., fit=...)`; the Link passes one).
Only a frame longer than a packet (an rmw_desert-profile payload over `max_read_length - 4` bytes;
native fragments are sized to fit a packet) is cut: it starts a write of its own, and its pieces
fill the following writes alone. The old cut-and-fill mode (`aligned=False`: the last frame of a
write is cut and its rest starts the next write) is kept for benchmarks only: one lost packet then
destroys up to two frames, and an rmw_desert receiver, which cannot resync inside a frame, loses more.

The last piece of a cut frame is written twice: alone, then again at the start of the next
write (`echo`), unless it holds `99 99`. A receiver that got it finds the repeat between two
frames and skips it, as any bytes outside a frame (section 2); one that lost it is still inside
the frame, LEN bytes counted, and the repeat completes the frame exactly. Without it an
rmw_desert receiver, which takes LEN + 1 bytes after a start whatever they hold, swallows the
next packet's frames with the lost tail (on real DESERT: the first 6-8 Twists after a
beacon straddling two packets; an rmw_desert beacon is 70-110 bytes, and the names it must
carry alone take more than a 64-byte packet: wire-format.md section 6). The cost is the tail's
bytes once, on a link that cuts only rmw_desert payloads longer than a packet.

A write opportunity that finds nothing to send costs nothing: the next frame goes out as soon as
it is offered (low latency when the link is idle).

Writes are spaced a little more than a period apart (`margin`, 5 % by default). Without it our
writes keep a fixed phase against DESERT's send ticks: if that phase happens to be just after a
tick, every packet waits almost a whole period in DESERT, and jitter in when DESERT reads the
socket occasionally lets two writes share one tick interval, so a second packet queues and stays
(another period of latency). A slightly slower pace slides our phase through DESERT's, so those
states do not last, and it also absorbs clock drift between us and DESERT. Measured against the
emulator (64 B / 0.2 s, 300 m, a 10 Hz command stream plus a flood): command latency median
0.60 s and p95 0.80 s without the margin, 0.50 s and 0.62-0.70 s with 5 %, for 5 % less throughput.
The margin is all the pace loses: a write the thread makes a little late (less than the margin)
does not push the following ones back (`Pacer.wrote`), and a saturated link fills its packets
(uwgen.runtime.link.filling), so link use is about 0.99 x 1 / 1.05 (benchmarks/envelope_bench.py).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from uwgen.manifest.model import LinkConfig
from uwgen.runtime.wire.framing import OVERHEAD, SYNC


DEFAULT_MARGIN = 0.05
MIN_FRAME = OVERHEAD + 1  # the shortest frame: nothing shorter fits the room left
PACKET_HEADER = 4        # bytes DESERT adds to each packet on the air (UDP and IP headers)


class Pacer:
    """At most one write, of at most `max_bytes`, per `period * (1 + margin)` seconds (writes due
    on a grid of that interval while the link is busy; see `wrote`).

    With `bitrate` (bit/s) the interval after a write is also at least that packet's time on the
    air, for links whose modem cannot send a full packet within one period.
    """

    def __init__(self, max_bytes: int, period: float, margin: float = 0.0, bitrate: float | None = None):
        if max_bytes < 1:
            raise ValueError(f"max_read_length must be at least 1, got {max_bytes}")
        if period <= 0:
            raise ValueError(f"period must be positive, got {period}")
        if not 0 <= margin < 1:
            raise ValueError(f"pace margin must be in [0, 1), got {margin}")
        if bitrate is not None and bitrate <= 0:
            raise ValueError(f"bitrate must be positive, got {bitrate}")
        self.max_bytes = max_bytes
        self.period = period
        self.margin = margin
        self.bitrate = bitrate
        self._next = float("-inf")

    @classmethod
    def for_link(cls, config: LinkConfig, margin: float = DEFAULT_MARGIN, bitrate: float | None = None) -> Pacer:
        return cls(config.max_read_length, config.period, margin, bitrate)

    @property
    def next_write_at(self) -> float:
        """Earliest time of the next write (-inf before the first)."""
        return self._next

    def may_write(self, now: float) -> bool:
        return now >= self._next

    def wrote(self, now: float, nbytes: int = 0) -> None:
        """A write happened at `now`. A write late by less than the margin (the thread woke a
        little after `next_write_at`) keeps the grid: the next interval counts from when this
        write was due, so the margin is what the pace loses, not the margin plus every wake-up's
        delay; two writes are still never less than one period apart. A later write (the link
        was idle) starts a new grid."""
        interval = self.period
        if self.bitrate is not None:
            interval = max(interval, (nbytes + PACKET_HEADER) * 8 / self.bitrate)
        slack = interval * self.margin
        base = self._next if 0.0 <= now - self._next <= slack else now
        self._next = base + interval * (1.0 + self.margin)


@dataclass
class OutboxStats:
    frames_sent: int = 0        # frames whose last byte was written
    frames_abandoned: int = 0   # frames cut (or lost in a failed write) by a disconnect
    bytes_sent: int = 0
    writes: int = 0


class Outbox:
    """Builds each paced write from frames pulled on demand; tracks which frames are complete.

    Use: `batch = take(now, pull)`; if non-empty, write it, then `sent(now)` on success or
    `abandon()` on failure. `abandon()` is also called when the connection is lost between writes,
    which cuts the long frame whose remaining pieces were waiting. A whole frame pulled but not yet
    written (it did not fit) survives a disconnect and goes first on the next connection.
    """

    def __init__(self, pacer: Pacer, aligned: bool = True, one_frame: bool = False,
                 echo: bool = True):
        self.pacer = pacer
        self.aligned = aligned
        self.one_frame = one_frame   # wire format 2: one frame (one envelope) per write
        self.echo = echo             # repeat a cut frame's last piece at the next write's start
        self.stats = OutboxStats()
        self._echo = b""             # that piece, until the next write
        self._rest = b""             # unwritten pieces of the frame cut by the last write
        self._held = b""             # a whole frame pulled that did not fit the last write
        self._batch_frames = 0       # frames the pending batch completes
        self._batch_len = 0

    @property
    def pending(self) -> bool:
        """A frame (a cut one's rest, or a whole one that did not fit) or an echo waits for the
        next write."""
        return bool(self._rest or self._held or self._echo)

    def take(self, now: float, pull: Callable[[], bytes | None],
             fit: Callable[[int], bytes | None] | None = None) -> bytes:
        """The next write, or b"" if it is not time yet or there is nothing to send.

        `pull()` returns the next whole frame, or None; it is called only while there is room.
        `fit(room)` (optional) returns the next frame of at most `room` bytes, or None (and never
        one of the channel whose frame is held): with it, the room left when the next frame in
        priority order does not fit is filled with the best frames that do.
        """
        if self._batch_len:
            raise RuntimeError("take() before the previous batch was sent() or abandon()ed")
        if not self.pacer.may_write(now):
            return b""
        if self.aligned:
            parts, frames = self._aligned(pull, fit)
        else:
            parts, frames = self._cut_and_fill(pull)
        batch = b"".join(parts)
        self._batch_frames = frames
        self._batch_len = len(batch)
        return batch

    def _aligned(self, pull: Callable[[], bytes | None],
                 fit: Callable[[int], bytes | None] | None) -> tuple[list[bytes], int]:
        room = self.pacer.max_bytes
        if self._rest:               # the next piece of a frame longer than a packet, alone
            piece, self._rest = self._rest[:room], self._rest[room:]
            if not self._rest and self.echo and SYNC not in piece and len(piece) < room:
                self._echo = piece   # repeated at the next write's start (module doc)
            return [piece], 0 if self._rest else 1
        parts: list[bytes] = []
        if self._echo:
            parts.append(self._echo)
            room -= len(self._echo)
            self._echo = b""
        echoed = len(parts)
        while room >= MIN_FRAME or len(parts) == echoed:
            frame, self._held = (self._held or pull()), b""
            if not frame:
                break
            if len(frame) <= room:
                parts.append(frame)
                room -= len(frame)
                if self.one_frame:
                    return parts, 1
            elif len(parts) > echoed:
                self._held = frame          # whole, at the start of the next write
                break
            elif echoed:                    # the echo and a frame longer than a packet: the
                self._held = frame          # echo alone, the frame cut from the next write
                break
            else:                           # longer than a packet: cut, in writes of its own
                self._rest = frame[room:]
                return [frame[:room]], 0
        # The next frame in priority order did not fit (it goes first next time, so nothing
        # starves): fill what is left with frames that fit, from the other channels.
        while fit is not None and len(parts) > echoed and room >= MIN_FRAME:
            frame = fit(room)
            if not frame:
                break
            parts.append(frame)
            room -= len(frame)
        return parts, len(parts) - echoed

    def _cut_and_fill(self, pull: Callable[[], bytes | None]) -> tuple[list[bytes], int]:
        room = self.pacer.max_bytes
        parts: list[bytes] = []
        frames = 0
        rest = self._rest
        if rest:
            parts.append(rest[:room])
            rest = rest[room:]
            room -= len(parts[-1])
            if not rest:
                frames += 1
        while room > 0 and not rest:
            frame = pull()
            if not frame:
                break
            parts.append(frame[:room])
            rest = frame[room:]
            room -= len(parts[-1])
            if not rest:
                frames += 1
        self._rest = rest
        return parts, frames

    def sent(self, now: float) -> None:
        """The batch from take() was written."""
        self.pacer.wrote(now, self._batch_len)
        self.stats.frames_sent += self._batch_frames
        self.stats.bytes_sent += self._batch_len
        self.stats.writes += 1
        self._clear_batch()

    def abandon(self, counted: bool = True) -> int:
        """The connection failed: drop the pending batch and the cut frame; return frames dropped
        (`counted` as abandoned; False: the connection counts them, a batch that came late).

        A whole frame held back for the next write is kept: none of its bytes went out.
        """
        lost = self._batch_frames + (1 if self._rest else 0)
        self.stats.frames_abandoned += lost if counted else 0
        self._rest = self._echo = b""
        self._clear_batch()
        return lost

    def _clear_batch(self) -> None:
        self._batch_frames = 0
        self._batch_len = 0
