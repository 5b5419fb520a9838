"""Fragments: payloads over 255 bytes carried as ordinary topic messages on a reserved id.

A frame carries at most 255 payload bytes (wire format section 2). A longer payload is split into
fragments, each an ordinary topic message (kind 0) on the manifest's `fragment_id`, so that it
stays within the wire format: only kind 0 on the wire, and an id that an rmw_desert peer does not
have in its table and therefore ignores. Layout (a CBOR sequence like every payload; see
docs/wire-format.md, section 7):

    0, fragment_id, transfer, index, count, chunk

- `transfer` (unsigned, 0..255): names the fragmented message; the sender counts up from a random
  start, modulo 256, so a restarted sender is unlikely to continue a number the receiver still holds;
- `index` (0..count-1) and `count` (1..255): position of this fragment and how many there are;
- `chunk` (byte string, at least 1 byte): chunks 0..count-2 have the same length, the last one is no
  longer; the original payload (which starts with its own kind and id) is their concatenation.

Repair fragments (wire format section 11): a message of k data fragments may be followed by r repair
fragments, `0, fragment_id, transfer, index, count, chunk, size` with index k..k+r-1 (so an older
receiver refuses them as malformed and still rebuilds from the data fragments), each chunk a block
of a systematic erasure code (uwgen.runtime.wire.fec) over the data chunks, the last padded with zeros,
and `size` the length of the original payload. Any k of the k + r fragments rebuild the message.

Every fragment payload is at most `max_payload` bytes (255, or less so that a fragment frame fits one
DESERT packet: the Link passes `max_read_length - 4`, see `fragment_payload_for`), so a lost packet
costs whole fragments only. The receiver's side, reassembly, is uwgen.runtime.wire.reassembly.
"""
from __future__ import annotations

import random
from dataclasses import dataclass

from uwgen.runtime.wire import fec
from uwgen.runtime.wire.envelope import H_FRAGMENT
from uwgen.runtime.wire.framing import MAX_PAYLOAD, OVERHEAD

FRAGMENT_KIND = 0
MAX_TRANSFER = 255
MAX_COUNT = 255
SIZE_ITEM = 3              # a repair fragment's `size` item: CBOR unsigned up to 65535


class FragmentError(ValueError):
    """A payload that is not a well-formed fragment, or a message too large to fragment."""


# -- CBOR, just the two item types a fragment uses ---------------------------------------------

def _uint(v: int, major: int = 0) -> bytes:
    m = major << 5
    if v < 24:
        return bytes((m | v,))
    if v < 0x100:
        return bytes((m | 24, v))
    if v < 0x10000:
        return bytes((m | 25,)) + v.to_bytes(2, "big")
    if v < 0x1_0000_0000:
        return bytes((m | 26,)) + v.to_bytes(4, "big")
    return bytes((m | 27,)) + v.to_bytes(8, "big")


def read_head(buf: bytes, pos: int, major: int, what: str) -> tuple[int, int]:
    """Read one definite-length item head of the given major type; return (value, next pos)."""
    if pos >= len(buf):
        raise FragmentError(f"fragment: {what} missing")
    b = buf[pos]
    if b >> 5 != major:
        raise FragmentError(f"fragment: {what} has CBOR major type {b >> 5}, expected {major}")
    info = b & 0x1F
    if info < 24:
        return info, pos + 1
    if info > 27:
        raise FragmentError(f"fragment: {what} has unsupported CBOR additional info {info}")
    size = 1 << (info - 24)
    if pos + 1 + size > len(buf):
        raise FragmentError(f"fragment: {what} truncated")
    return int.from_bytes(buf[pos + 1:pos + 1 + size], "big"), pos + 1 + size


@dataclass(frozen=True)
class Fragment:
    transfer: int
    index: int
    count: int                 # data fragments of the message (k)
    chunk: bytes
    size: int | None = None    # repair fragments only: length of the whole message

    @property
    def is_repair(self) -> bool:
        return self.index >= self.count


def is_fragment(payload: bytes, fragment_id: int | None, compact: bool = False) -> bool:
    """Cheap test of the header: is this payload `0, fragment_id, ...` (or, with `compact`, a
    wire format 2 fragment message, H 0x61)?"""
    if fragment_id is None:
        return False
    if compact and payload[:1] == COMPACT_H:
        return True
    if len(payload) < 2 or payload[0] != FRAGMENT_KIND:
        return False
    head = _uint(fragment_id)
    return payload[1:1 + len(head)] == head


def parse_fragment(payload: bytes, fragment_id: int) -> Fragment:
    """Decode one fragment payload; raise FragmentError saying what is wrong."""
    kind, pos = read_head(payload, 0, 0, "kind")
    if kind != FRAGMENT_KIND:
        raise FragmentError(f"fragment: kind {kind}, expected {FRAGMENT_KIND}")
    ident, pos = read_head(payload, pos, 0, "id")
    if ident != fragment_id:
        raise FragmentError(f"fragment: id {ident}, expected {fragment_id}")
    transfer, pos = read_head(payload, pos, 0, "transfer")
    index, pos = read_head(payload, pos, 0, "index")
    count, pos = read_head(payload, pos, 0, "count")
    size, pos = read_head(payload, pos, 2, "chunk")
    if transfer > MAX_TRANSFER:
        raise FragmentError(f"fragment: transfer {transfer} out of range 0..{MAX_TRANSFER}")
    if not 1 <= count <= MAX_COUNT:
        raise FragmentError(f"fragment: count {count} out of range 1..{MAX_COUNT}")
    if size == 0:
        raise FragmentError("fragment: empty chunk")
    if pos + size > len(payload) or (index < count and pos + size != len(payload)):
        raise FragmentError(f"fragment: chunk of {size} bytes but {len(payload) - pos} bytes follow")
    chunk, pos = bytes(payload[pos:pos + size]), pos + size
    if index < count:
        return Fragment(transfer, index, count, chunk)
    # A repair fragment: index count..count+r-1, then the message size.
    if index >= fec.MAX_BLOCKS:
        raise FragmentError(f"fragment: repair index {index} out of range {count}..{fec.MAX_BLOCKS - 1}")
    if pos == len(payload):
        raise FragmentError(f"fragment: index {index} not below count {count}, and no size item after "
                            f"the chunk (a repair fragment has one)")
    total, pos = read_head(payload, pos, 0, "size of a repair fragment")
    if pos != len(payload):
        raise FragmentError(f"fragment: {len(payload) - pos} bytes after the size of a repair fragment")
    if not (count - 1) * size < total <= count * size:
        raise FragmentError(f"fragment: size {total} cannot be {count} chunks of at most {size} bytes")
    return Fragment(transfer, index, count, chunk, total)


# -- the compact fragment message of wire format 2 (docs/wire-format.md section 14) ------------
#
#     61 | transfer | index | count | [size: 2 bytes, big-endian; repair fragments only] | chunk
#
# H 0x61 (the envelope's escape code with id bits 1) says "fragment" without an id, and the
# chunk needs no byte-string head: the message's length (or the envelope's end) says it.

COMPACT_H = bytes((H_FRAGMENT,))
COMPACT_HEAD = 4            # H, transfer, index, count
COMPACT_SIZE = 2            # a repair fragment's size


def encode_compact(f: Fragment) -> bytes:
    """A fragment as a wire format 2 fragment message (H included); FragmentError when a field
    does not fit its byte."""
    if not (0 <= f.transfer <= MAX_TRANSFER and 0 <= f.index <= 255 and 1 <= f.count <= MAX_COUNT):
        raise FragmentError(f"fragment: transfer {f.transfer}, index {f.index}, count {f.count} "
                            "do not fit a byte each")
    if not f.chunk:
        raise FragmentError("fragment: empty chunk")
    size = b""
    if f.is_repair:
        if f.size is None or not 0 < f.size < 1 << 16:
            raise FragmentError(f"repair fragment: size {f.size} does not fit 2 bytes")
        size = f.size.to_bytes(COMPACT_SIZE, "big")
    return COMPACT_H + bytes((f.transfer, f.index, f.count)) + size + bytes(f.chunk)


def parse_compact(payload: bytes) -> Fragment:
    """The fragment in a wire format 2 fragment message; FragmentError saying what is wrong."""
    b = bytes(payload)
    if b[:1] != COMPACT_H:
        raise FragmentError("fragment message: H is not 61")
    if len(b) < COMPACT_HEAD + 1:
        raise FragmentError(f"fragment message of {len(b)} bytes: at least {COMPACT_HEAD + 1}")
    transfer, index, count = b[1], b[2], b[3]
    if count == 0:
        raise FragmentError("fragment: count 0")
    if index < count:
        return Fragment(transfer, index, count, b[COMPACT_HEAD:])
    if index >= fec.MAX_BLOCKS:
        raise FragmentError(f"fragment: repair index {index} out of range {count}..{fec.MAX_BLOCKS - 1}")
    chunk = b[COMPACT_HEAD + COMPACT_SIZE:]
    if not chunk:
        raise FragmentError("repair fragment: no size and chunk after its head")
    total = int.from_bytes(b[COMPACT_HEAD:COMPACT_HEAD + COMPACT_SIZE], "big")
    if not (count - 1) * len(chunk) < total <= count * len(chunk):
        raise FragmentError(f"fragment: size {total} cannot be {count} chunks of at most {len(chunk)} bytes")
    return Fragment(transfer, index, count, chunk, total)


def parse_any(payload: bytes, fragment_id: int) -> Fragment:
    """A fragment in either form: compact (H 0x61) or wire format 1's CBOR items."""
    return parse_compact(payload) if payload[:1] == COMPACT_H else parse_fragment(payload, fragment_id)


def encode_fragment(fragment_id: int, f: Fragment) -> bytes:
    parts = [_uint(FRAGMENT_KIND), _uint(fragment_id), _uint(f.transfer), _uint(f.index),
             _uint(f.count), _uint(len(f.chunk), 2), f.chunk]
    if f.size is not None:
        parts.append(_uint(f.size))
    return b"".join(parts)


# -- sender ------------------------------------------------------------------------------------

MIN_FRAGMENT_PAYLOAD = 24     # below this a fragment would be mostly header: cut the frame instead
MIN_COMPACT_PAYLOAD = 8       # compact fragments: 4 bytes of head, 2 of size, some chunk


def fragment_payload_for(max_read_length: int) -> int:
    """The largest fragment payload whose frame fits one DESERT packet (within 24..255 bytes)."""
    return max(MIN_FRAGMENT_PAYLOAD, min(MAX_PAYLOAD, max_read_length - OVERHEAD))


class Fragmenter:
    """Splits payloads over 255 bytes into fragment payloads of at most `max_payload` bytes each."""

    def __init__(self, fragment_id: int, *, rng: random.Random | None = None,
                 max_fragments: int = MAX_COUNT, max_payload: int = MAX_PAYLOAD,
                 compact: bool = False):
        """`compact`: fragments are wire format 2 fragment messages (`encode_compact`), each at
        most `max_payload` bytes H included; else wire format 1 fragment payloads."""
        if not 1 <= fragment_id <= 255:
            raise ValueError(f"fragment_id must be 1..255, got {fragment_id}")
        if not 2 <= max_fragments <= MAX_COUNT:
            raise ValueError(f"max_fragments must be 2..{MAX_COUNT}, got {max_fragments}")
        least = MIN_COMPACT_PAYLOAD if compact else MIN_FRAGMENT_PAYLOAD
        if not least <= max_payload <= MAX_PAYLOAD:
            raise ValueError(f"max_payload must be {least}..{MAX_PAYLOAD}, got {max_payload}")
        self.compact = compact
        self.fragment_id = fragment_id
        self.max_fragments = max_fragments
        self.max_payload = max_payload
        self._next_transfer = (rng or random.Random()).randrange(MAX_TRANSFER + 1)
        self.max_message_size = self.max_message_for(0)

    def max_message_for(self, repair: int) -> int:
        """The largest payload that can be split with `repair` repair fragments."""
        k = self.max_fragments - repair
        return self._chunk_size(k, repair) * k if k >= 1 else 0

    def _chunk_size(self, count: int, repair: int = 0) -> int:
        """Largest chunk such that the fragment with the widest header still fits max_payload."""
        if self.compact:
            return self.max_payload - COMPACT_HEAD - (COMPACT_SIZE if repair else 0)
        head = (1 + len(_uint(self.fragment_id)) + len(_uint(MAX_TRANSFER))
                + len(_uint(count + repair - 1)) + len(_uint(count)))
        size = self.max_payload - head - 2       # byte string head: at most 2 bytes up to 255
        if repair:
            size -= SIZE_ITEM
        return size

    def plan(self, size: int, repair: int = 0) -> tuple[int, int]:
        """(count, chunk size) for a payload of `size` bytes; FragmentError if too large."""
        most = self.max_fragments - repair
        count = 2
        while True:
            chunk = self._chunk_size(count, repair)
            need = -(-size // chunk)
            if need <= count:
                count = max(need, 1)
                break
            count = need
            if count > most:
                raise FragmentError(
                    f"payload of {size} bytes needs more than {most} fragments "
                    f"(at most {self.max_message_for(repair)} bytes can be fragmented"
                    + (f" with {repair} repair fragments)" if repair else ")"))
        return count, chunk

    def split(self, payload: bytes, repair: int = 0) -> list[bytes]:
        """Fragment payloads for one message (a new transfer number each call): the data
        fragments in order, then `repair` repair fragments."""
        if len(payload) == 0:
            raise FragmentError("cannot fragment an empty payload")
        count, chunk = self.plan(len(payload), repair)
        transfer = self._next_transfer
        self._next_transfer = (transfer + 1) % (MAX_TRANSFER + 1)
        chunks = [payload[i * chunk:(i + 1) * chunk] for i in range(count)]
        frags = [Fragment(transfer, i, count, c) for i, c in enumerate(chunks)]
        if repair:
            width = len(chunks[0])
            blocks = fec.repair_blocks([c.ljust(width, b"\0") for c in chunks], repair)
            frags += [Fragment(transfer, count + j, count, b, len(payload)) for j, b in enumerate(blocks)]
        out = [encode_compact(f) if self.compact else encode_fragment(self.fragment_id, f) for f in frags]
        assert all(len(p) <= self.max_payload for p in out)
        return out
