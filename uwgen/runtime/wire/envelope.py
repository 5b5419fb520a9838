"""The packet envelope of wire format 4 (docs/wire-format.md section 14, docs/seams.md sections 1
and 11).

A link of profile `native` or `packed` writes one frame per DESERT write, and that frame's payload
is one envelope:

    P | W | [K] | [T] | [A] | [C] | M1 M2 ... Mn | [tag]

- P (1 byte): bits 7-5 the version (`100` = 4; `011` was wire format 3, without cut
  messages; `010` wire format 2, without runs either), then flags S (sealed: a tag ends the
  envelope; 8 bytes, or the link's `security: {tag_bytes}`), K, T, A, C (which optional parts
  follow);
- W (2 bytes, big-endian): sender id (bits 15-12), packet number mod 4096 (bits 11-0);
- K (10 bytes): the sender's epoch (6 bytes) and packet number bits 12-43 (4 bytes, big-endian);
- T (3 bytes): the sender's clock at sealing, 24-bit count of 1/32 s, big-endian;
- A and C (1 + L bytes each): L, then L opaque bytes (acknowledgements; security control);
- messages: each `H [len] body`, and runs of messages sharing one head
  (uwgen.runtime.wire.messages says how).

This module is pure: bytes in, an `Envelope` out (or one `EnvelopeError`), and back. It interprets
P, W and the messages; K, T, A, C and the tag are carried as values and bytes for their owners
(security, commands). How long a tag is, is not in the bytes: `decode` is told it (`tag_len`,
the link's setting, default 8). Every envelope has exactly one encoding: `decode` refuses what `encode`
would never write (a length on the last message, an id escape for an id that fits H, ...), so
`encode(decode(b)) == b` for every accepted `b`.

The transition helpers `from_v1` / `to_v1` (uwgen.runtime.wire.v1payload, re-exported here) turn a
wire format 1 payload (CBOR kind and id items, then the rest) into a message and back, so
generated codecs need not change.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.manifest.model import DEFAULT_TAG_BYTES, TAG_BYTES
from uwgen.runtime.wire.messages import (  # noqa: F401 (this module's interface)
    CODE_KINDS, CUT_HEAD, CUT_TAIL, ESCAPE_CODE, FRAGMENT, H_CUT_HEAD, H_CUT_TAIL, H_FRAGMENT,
    H_LENGTH, H_RUN, KIND_CODES, MAX_BODY, RUN_MAX,
    RUN_MIN, SHORT_IDS, EnvelopeError, Message, blocks, decode_messages, encode_messages,
    is_fragment_message, messages_size, ordered)
from uwgen.runtime.wire.v1payload import (  # noqa: F401 (this module's interface)
    add_packed_head, from_v1, strip_packed_head, to_v1, v1_message_size)

VERSION = 4                 # the envelope this build speaks (the schema fingerprint hashes it)
VERSION_MASK = 0xE0
VERSION_BITS = VERSION << 5          # 0x80
FLAG_S, FLAG_K, FLAG_T, FLAG_A, FLAG_C = 0x10, 0x08, 0x04, 0x02, 0x01

HEAD = 3                    # P and W
EPOCH_LEN = 6
SYNC_LEN = EPOCH_LEN + 4    # K
TIME_LEN = 3                # T
TAG_LEN = DEFAULT_TAG_BYTES            # the tag of a sealed envelope unless the link says otherwise
TAG_LENGTHS = TAG_BYTES                # what a link may say (manifest `security: {tag_bytes}`)
MAX_SENDER = 15
NUMBER_MOD = 4096           # W carries the packet number's low 12 bits
MAX_PAYLOAD = 255           # an envelope is one frame's payload (wire format section 2)
MAX_PART = 255              # A and C: a one-byte length


@dataclass(frozen=True)
class Sync:
    """K: the sender's epoch (6 bytes) and its packet number's bits 12-43."""

    epoch: bytes
    high: int

    def encode(self) -> bytes:
        if len(self.epoch) != EPOCH_LEN:
            raise EnvelopeError(f"epoch must be {EPOCH_LEN} bytes, got {len(self.epoch)}")
        if not 0 <= self.high < 1 << 32:
            raise EnvelopeError(f"packet number bits 12-43 must fit 32 bits, got {self.high}")
        return bytes(self.epoch) + self.high.to_bytes(4, "big")


@dataclass(frozen=True)
class Envelope:
    """One packet's envelope; see the module docstring for the meaning of each part."""

    sender: int
    number: int                       # packet number mod 4096
    messages: tuple[Message, ...] = ()
    sync: Sync | None = None          # K
    time: int | None = None           # T: 24-bit count of 1/32 s
    ack: bytes | None = None          # A
    control: bytes | None = None      # C
    tag: bytes | None = None          # present exactly when sealed (S)

    @property
    def sealed(self) -> bool:
        return self.tag is not None

    def encode(self) -> bytes:
        """The envelope's bytes (a frame payload); EnvelopeError if any part is out of range."""
        out = bytearray(self.encode_head())
        out += encode_messages(self.messages)
        if self.tag is not None:
            if len(self.tag) not in TAG_LENGTHS:
                raise EnvelopeError(f"tag must be {_lengths()} bytes, got {len(self.tag)}")
            out += self.tag
        if len(out) > MAX_PAYLOAD:
            raise EnvelopeError(f"envelope of {len(out)} bytes: a frame holds at most {MAX_PAYLOAD}")
        return bytes(out)

    def encode_head(self) -> bytes:
        """P, W and the optional parts: everything before the messages."""
        if not 0 <= self.sender <= MAX_SENDER:
            raise EnvelopeError(f"sender id must be 0..{MAX_SENDER}, got {self.sender}")
        if not 0 <= self.number < NUMBER_MOD:
            raise EnvelopeError(f"packet number must be 0..{NUMBER_MOD - 1} (mod {NUMBER_MOD}), "
                                f"got {self.number}")
        p = VERSION_BITS
        parts = bytearray()
        if self.tag is not None:
            p |= FLAG_S
        if self.sync is not None:
            p |= FLAG_K
            parts += self.sync.encode()
        if self.time is not None:
            if not 0 <= self.time < 1 << 24:
                raise EnvelopeError(f"time must fit 24 bits, got {self.time}")
            p |= FLAG_T
            parts += self.time.to_bytes(TIME_LEN, "big")
        for flag, value, what in ((FLAG_A, self.ack, "acknowledgement"),
                                  (FLAG_C, self.control, "control")):
            if value is not None:
                if len(value) > MAX_PART:
                    raise EnvelopeError(f"{what} part of {len(value)} bytes: at most {MAX_PART}")
                p |= flag
                parts += bytes((len(value),)) + bytes(value)
        return bytes((p,)) + ((self.sender << 12) | self.number).to_bytes(2, "big") + bytes(parts)

    def head_size(self) -> int:
        """Bytes of P, W and the optional parts, plus the tag when sealed: what a packet pays
        besides its messages."""
        return len(self.encode_head()) + (len(self.tag) if self.tag is not None else 0)



def _lengths() -> str:
    return ", ".join(map(str, TAG_LENGTHS[:-1])) + f" or {TAG_LENGTHS[-1]}"


def decode(data: bytes | bytearray | memoryview, tag_len: int = TAG_LEN) -> Envelope:
    """The envelope in `data`, whose tag (when S is set) is `tag_len` bytes (its link's
    setting); EnvelopeError (and nothing else) for any bytes that are not one."""
    if tag_len not in TAG_LENGTHS:
        raise ValueError(f"a link's tag is {_lengths()} bytes, not {tag_len}")
    b = bytes(data)
    n = len(b)
    if n < HEAD:
        if n and b[0] & VERSION_MASK != VERSION_BITS:
            raise EnvelopeError(f"not a wire format {VERSION} envelope (version bits {b[0] >> 5})",
                                version=b[0] >> 5)
        raise EnvelopeError(f"envelope of {n} bytes: at least {HEAD} (P and W)")
    if n > MAX_PAYLOAD:
        raise EnvelopeError(f"envelope of {n} bytes: a frame holds at most {MAX_PAYLOAD}")
    p = b[0]
    if p & VERSION_MASK != VERSION_BITS:
        raise EnvelopeError(f"not a wire format {VERSION} envelope (version bits {p >> 5})",
                            version=p >> 5)
    w = int.from_bytes(b[1:3], "big")
    pos = HEAD
    end = n - tag_len if p & FLAG_S else n
    if end < pos:
        raise EnvelopeError(f"sealed envelope of {n} bytes: too short for its {tag_len}-byte tag")
    sync = time = ack = control = None
    if p & FLAG_K:
        if pos + SYNC_LEN > end:
            raise EnvelopeError("envelope ends inside its sync part (K)")
        sync = Sync(b[pos:pos + EPOCH_LEN], int.from_bytes(b[pos + EPOCH_LEN:pos + SYNC_LEN], "big"))
        pos += SYNC_LEN
    if p & FLAG_T:
        if pos + TIME_LEN > end:
            raise EnvelopeError("envelope ends inside its time part (T)")
        time = int.from_bytes(b[pos:pos + TIME_LEN], "big")
        pos += TIME_LEN
    if p & FLAG_A:
        ack, pos = _part(b, pos, end, "acknowledgement (A)")
    if p & FLAG_C:
        control, pos = _part(b, pos, end, "control (C)")
    messages = decode_messages(b, pos, end)
    return Envelope(sender=w >> 12, number=w & (NUMBER_MOD - 1), messages=messages,
                    sync=sync, time=time, ack=ack, control=control,
                    tag=b[end:] if p & FLAG_S else None)


def _part(b: bytes, pos: int, end: int, what: str) -> tuple[bytes, int]:
    if pos >= end:
        raise EnvelopeError(f"envelope ends before the length of its {what} part")
    size = b[pos]
    if pos + 1 + size > end:
        raise EnvelopeError(f"{what} part of {size} bytes does not fit the envelope")
    return b[pos + 1:pos + 1 + size], pos + 1 + size
