"""Frames on the DESERT byte stream: `0x99 0x99 LEN payload[LEN] 0x55` (wire format, section 2).

DESERT cuts and glues the byte stream at arbitrary points and a lost acoustic packet removes an
arbitrary slice of it, so the decoder is incremental (fed whatever `recv()` returned) and
self-synchronising: it hunts for `0x99 0x99`, reads LEN, takes LEN bytes and requires `0x55` after
them; on any mismatch it discards the first `0x99` and hunts again from the next byte. A lost slice
therefore costs only the frames it touched.

The decoder never holds more than one incomplete frame (at most 258 bytes) between calls, plus the
chunk being processed during a call, and it counts every byte it throws away. It works with
`bytes.find`, not a per-byte Python loop, because it runs for every byte received.

Limits of the format (no checksum): a frame damaged by a lost slice can, by chance, be followed by a
`0x55` exactly LEN bytes later and then be delivered with wrong content (swallowing the frames it
overlaps), and a lost slice can hide the frame right after it. Only the payload decoder can catch a
false frame. tests/runtime/test_framing.py states what provably survives damage: for instance, when
payloads hold no 0x99 byte, every intact frame preceded by 258 undamaged bytes is delivered exactly
once and in order, whatever garbage or loss came before.
"""
from __future__ import annotations

from dataclasses import dataclass

SYNC = b"\x99\x99"
SYNC_BYTE = 0x99
END_BYTE = 0x55
MAX_PAYLOAD = 255
OVERHEAD = 4                      # 0x99 0x99 LEN ... 0x55
MAX_FRAME = MAX_PAYLOAD + OVERHEAD
MAX_PENDING = MAX_FRAME - 1       # the most an incomplete frame can occupy in the buffer


class FrameError(ValueError):
    """A payload that cannot be put in one frame (empty, or longer than 255 bytes)."""


def encode_frame(payload: bytes | bytearray | memoryview) -> bytes:
    """Wrap one payload (1 to 255 bytes) in a frame.

    Longer payloads must be fragmented (uwgen.runtime.wire.fragment) before they get here; rmw_desert
    wraps LEN modulo 256 instead, which is ambiguous, so we refuse.
    """
    n = len(payload)
    if not 1 <= n <= MAX_PAYLOAD:
        raise FrameError(
            f"frame payload must be 1 to {MAX_PAYLOAD} bytes, got {n}"
            + (" (fragment it or make it smaller)" if n > MAX_PAYLOAD else ""))
    return b"".join((SYNC, bytes((n,)), payload, b"\x55"))


@dataclass
class DecoderStats:
    """What the decoder has seen and thrown away (all counters only grow)."""

    bytes_received: int = 0    # every byte fed
    frames: int = 0            # frames delivered
    bytes_discarded: int = 0   # bytes that were not part of a delivered frame
    bad_length: int = 0        # a `0x99 0x99 0x00` start: LEN 0 is never valid
    bad_terminator: int = 0    # a start whose byte after LEN payload bytes was not 0x55
    stalled: int = 0           # incomplete frames given up by flush() (nothing more arrived)
    reset: int = 0             # incomplete frames thrown away by reset() (connection lost)


class FrameDecoder:
    """Incremental frame decoder: `feed(chunk)` returns the payloads completed by that chunk.

    Following wire format section 2 exactly, it is a pure function of the byte stream: how the
    stream is cut into chunks never changes what is delivered.
    """

    def __init__(self) -> None:
        self._buf = bytearray()      # unprocessed tail: an incomplete frame or a lone trailing 0x99
        self.stats = DecoderStats()

    @property
    def buffered(self) -> int:
        """Bytes held between calls (never more than MAX_PENDING = 258)."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        """Consume one chunk of the stream; return the payloads of the frames it completed, in order."""
        st = self.stats
        st.bytes_received += len(data)
        if self._buf:
            self._buf += data
            src: bytes | bytearray = self._buf
        else:
            src = bytes(data)
        out, pos = self._scan(src, 0)
        self._keep(src, pos)
        return out

    def flush(self) -> list[bytes]:
        """Give up the incomplete frame at the head of the buffer, hunt through what is left, empty it.

        Called when nothing has arrived for a while (see DesertConnection's stall timeout): a start
        whose LEN promises bytes that never come would otherwise hold back the frames behind it
        until enough unrelated bytes arrive. Giving up is the same move as a mismatch: discard the
        first 0x99 and hunt again from the next byte.
        """
        out: list[bytes] = []
        src = bytes(self._buf)
        pos = 0
        while src[pos:pos + 2] == SYNC:
            # An incomplete start is at pos (after a scan the tail is that or at most one 0x99).
            self.stats.stalled += 1
            self.stats.bytes_discarded += 1
            more, pos = self._scan(src, pos + 1)
            out += more
        # What is left is at most a lone 0x99 whose partner never came: stale too. Emptying the
        # buffer also tells the caller there is nothing left to wait for.
        self.stats.bytes_discarded += len(src) - pos
        self._buf = bytearray()
        return out

    def reset(self) -> None:
        """Forget the buffered bytes: the stream was interrupted (disconnect), so they cannot continue."""
        if self._buf:
            self.stats.reset += 1
            self.stats.bytes_discarded += len(self._buf)
            self._buf = bytearray()

    # -- internals -----------------------------------------------------------------------------

    def _scan(self, src: bytes | bytearray, pos: int) -> tuple[list[bytes], int]:
        """Deliver every complete frame in src[pos:]; return them and where the unprocessed tail starts."""
        st = self.stats
        out: list[bytes] = []
        n = len(src)
        find = src.find
        discarded = 0
        while True:
            i = find(SYNC, pos)
            if i < 0:
                # Keep a trailing 0x99: it may be the first half of a start split across chunks.
                end = n - 1 if n > pos and src[n - 1] == SYNC_BYTE else n
                discarded += end - pos
                pos = end
                break
            discarded += i - pos
            pos = i
            if n - pos < 3:
                break                                  # LEN not here yet
            length = src[pos + 2]
            if length == 0:
                st.bad_length += 1
                discarded += 1
                pos += 1
                continue
            end = pos + 3 + length                     # index of the terminator
            if end >= n:
                break                                  # frame not complete yet
            if src[end] == END_BYTE:
                out.append(bytes(src[pos + 3:end]))
                pos = end + 1
            else:
                st.bad_terminator += 1
                discarded += 1
                pos += 1
        st.bytes_discarded += discarded
        st.frames += len(out)
        return out, pos

    def _keep(self, src: bytes | bytearray, pos: int) -> None:
        if src is self._buf:
            del self._buf[:pos]
        else:
            self._buf = bytearray(src[pos:])


# -- the short frame: `LEN payload` (envelope links, docs/wire-format.md section 14.1) -----------

SHORT_OVERHEAD = 1                # LEN
# An envelope's P carries the version bits this build speaks (envelope.VERSION_BITS; generated
# packages carry this module without the envelope's, so the bits are repeated here, and
# tests/runtime/test_framing.py holds the two equal).
ENVELOPE_MASK, ENVELOPE_BITS = 0xE0, 0x80    # version bits 100: wire format 4
# A start is also taken when P says wire format 3 (the first short frame's envelope), so the
# envelope layer can count and log a peer of that build (`version_3`) instead of the frame
# decoder discarding its packets as noise; `check` decides whether the bytes are one.
START_BITS = (ENVELOPE_BITS, 0x60)


def encode_short_frame(payload: bytes | bytearray | memoryview) -> bytes:
    """`LEN payload`: the frame of links that speak only uwgen (the envelope's wire format).
    The payload is an envelope: its first byte carries this build's version bits (FrameError
    otherwise)."""
    n = len(payload)
    if not 1 <= n <= MAX_PAYLOAD:
        raise FrameError(f"frame payload must be 1 to {MAX_PAYLOAD} bytes, got {n}")
    if payload[0] & ENVELOPE_MASK != ENVELOPE_BITS:
        raise FrameError(f"a short frame carries an envelope (P {payload[0]:02X} is not one)")
    return bytes((n,)) + bytes(payload)


class ShortFrameDecoder(FrameDecoder):
    """Incremental decoder of short frames, `LEN payload`, with the FrameDecoder's interface.

    A frame starts where the previous one ended. A start is taken when LEN is not 0, the byte
    after it carries an envelope's version bits (`START_BITS`) and `check(payload)` (the envelope's
    total decoding, given by the link) accepts the LEN bytes; otherwise the first byte is
    discarded and the next one tried, so a lost slice that cut a frame costs the frames it
    touched and a few bytes of hunting. A long frame (`99 99 LEN payload 55`, a peer of wire
    format 1 or 2) is delivered as well, so the envelope layer can count and log what the far
    side speaks; the one short frame that also looks like a long one (LEN 0x99 and P 0x99, a
    153-byte sealed envelope with K and C) is taken as the short frame when it is complete and
    its envelope decodes (`_short_frame_at`).
    """

    def __init__(self, check=None) -> None:
        super().__init__()
        self.check = check

    def _scan(self, src: bytes | bytearray, pos: int) -> tuple[list[bytes], int]:
        st = self.stats
        out: list[bytes] = []
        n = len(src)
        discarded = 0
        while pos < n:
            length = src[pos]
            if length == SYNC_BYTE:                       # a long frame, or a byte to skip
                if pos + 1 >= n or (src[pos + 1] == SYNC_BYTE and pos + 2 >= n):
                    break                                  # not known yet
                size = src[pos + 2] if src[pos + 1] == SYNC_BYTE else 0
                if size:
                    end = pos + 3 + size
                    if end >= n:
                        break                              # not complete yet
                    if src[end] == END_BYTE and not self._short_frame_at(src, pos):
                        out.append(bytes(src[pos + 3:end]))
                        pos = end + 1
                        continue
            if length == 0:
                st.bad_length += 1
                discarded += 1
                pos += 1
                continue
            if pos + 1 < n and src[pos + 1] & ENVELOPE_MASK not in START_BITS:
                discarded += 1
                pos += 1
                continue
            if pos + 1 + length > n:
                break                                      # not complete yet
            payload = bytes(src[pos + 1:pos + 1 + length])
            if self.check is not None and not self.check(payload):
                st.bad_terminator += 1
                discarded += 1
                pos += 1
                continue
            out.append(payload)
            pos += 1 + length
        st.bytes_discarded += discarded
        st.frames += len(out)
        return out, pos

    def _short_frame_at(self, src: bytes | bytearray, pos: int) -> bool:
        """Whether a short frame of LEN 0x99 starts at `pos` although a long frame seems to:
        an envelope of 153 bytes whose P is 0x99 (version 4 with S, K and C), complete and
        accepted by `check`; it is preferred, since a long frame comes only from a peer of
        another wire format, whose packets are refused anyway."""
        end = pos + 1 + SYNC_BYTE
        return (self.check is not None and end <= len(src)
                and src[pos + 1] & ENVELOPE_MASK == ENVELOPE_BITS
                and bool(self.check(bytes(src[pos + 1:end]))))

    def flush(self) -> list[bytes]:
        """Give up the incomplete frame at the head of the buffer and hunt through the rest."""
        out: list[bytes] = []
        src = bytes(self._buf)
        pos = 0
        while pos < len(src):
            self.stats.stalled += 1
            self.stats.bytes_discarded += 1
            more, pos = self._scan(src, pos + 1)
            out += more
        self._buf = bytearray()
        return out


@dataclass(frozen=True)
class Framing:
    """How a link cuts its byte stream into frames: the long frame of section 2 (every link of
    wire format 1: rmw_desert nodes read it) or the short one (links that speak only uwgen)."""

    overhead: int
    encode: object
    decoder: object

    def new_decoder(self, check=None) -> FrameDecoder:
        return self.decoder(check) if self.decoder is ShortFrameDecoder else self.decoder()


LONG = Framing(OVERHEAD, encode_frame, FrameDecoder)
SHORT = Framing(SHORT_OVERHEAD, encode_short_frame, ShortFrameDecoder)
