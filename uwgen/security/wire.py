"""The protected payload (docs/wire-format.md section 12): pure functions, no state.

    protected = H | W | X | B | T

- H: the payload's header items as sent unprotected (kind, id, and the seq of a service
  payload), unchanged: routing by (kind, id) and fragments work as before;
- W: the security word, 2 bytes big-endian: sender id (4 bits), L (1 bit), the low 11
  bits of the sender's packet number;
- X: only when L = 1 (a *sync* word), 13 bytes: the number's bits 11..42 (4 bytes
  big-endian), the sender's epoch (6 bytes) and its clock when it sealed the frame (3 bytes,
  `freshness.stamp`);
- B: the message fields: as they are (mode sign) or AES-CCM ciphertext (mode encrypt,
  same length);
- T: the 8-byte AES-CCM tag.

Key: the working key of (sender, epoch) (`keys.working_key`). Nonce (13 bytes, as OSCORE):
sender id, 6 zero bytes, the number in 6 bytes big-endian; unique because an epoch is
random and new at every start of a sender and its numbers are counted in memory. Authenticated
data: version 2, mode (1 sign, 2 encrypt), sender id, fingerprint length and the fingerprint,
H, W and X; in mode sign also B (the plaintext is empty, so the tag authenticates everything
and the fields stay readable). The sync flag, the epoch and the time are thus under the tag:
adding a sync word to a recorded frame makes its tag fail.
"""
from __future__ import annotations

from dataclasses import dataclass

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives.ciphers.aead import AESCCM

SIGN = "sign"
ENCRYPT = "encrypt"
OFF = "off"
MODES = (OFF, SIGN, ENCRYPT)
MODE_CODE = {SIGN: 1, ENCRYPT: 2}
VERSION = 2                                           # 2: epochs, W and X in the aad

TAG_BYTES = 8
NONCE_BYTES = 13
WORD_BYTES = 2
HIGH_BYTES = 4
EPOCH_BYTES = 6
TIME_BYTES = 3
SYNC_BYTES = HIGH_BYTES + EPOCH_BYTES + TIME_BYTES    # 13
OVERHEAD = WORD_BYTES + TAG_BYTES                     # every frame but sync frames: 10
SYNC_OVERHEAD = WORD_BYTES + SYNC_BYTES + TAG_BYTES   # a sync frame: 23
MAX_SENDER = 15
PARTIAL_BITS = 11
PARTIAL_MASK = (1 << PARTIAL_BITS) - 1
LONG_FLAG = 1 << PARTIAL_BITS
MAX_SEQ = (1 << (PARTIAL_BITS + 8 * HIGH_BYTES)) - 1  # 2**43 - 1

__all__ = ["InvalidTag", "Parsed", "Sync", "new_aead", "header_length", "seal", "parse", "open_parsed"]


class MalformedError(ValueError):
    """Too short to hold a header, the security word and a tag."""


@dataclass(frozen=True)
class Sync:
    """What a sync word says besides the number: the sender's epoch and its sealing time."""

    epoch: bytes           # EPOCH_BYTES random bytes, new at every start of the sender
    time: int              # freshness.stamp() of the sender's clock, 24 bits


def new_aead(key: bytes, tag_bytes: int = TAG_BYTES) -> AESCCM:
    """AES-CCM under `key` with tags of `tag_bytes` (8 per payload; a wire format 2 link's
    `security: {tag_bytes}` per packet)."""
    return AESCCM(key, tag_length=tag_bytes)


def header_length(payload: bytes) -> tuple[int, int, int]:
    """(kind, id, length of H): kind and id, plus the seq when kind is 2 or 3."""
    pos = 0
    values = []
    want = 2
    while len(values) < want:
        if pos >= len(payload):
            raise MalformedError("payload ended inside its header")
        head = payload[pos]
        if head >> 5 != 0:
            raise MalformedError(f"header item {len(values)} is not an unsigned integer")
        info = head & 0x1F
        if info < 24:
            value, pos = info, pos + 1
        elif info <= 27:
            size = 1 << (info - 24)
            if pos + 1 + size > len(payload):
                raise MalformedError("payload ended inside its header")
            value, pos = int.from_bytes(payload[pos + 1:pos + 1 + size], "big"), pos + 1 + size
        else:
            raise MalformedError(f"header item {len(values)} has CBOR additional info {info}")
        values.append(value)
        if len(values) == 1 and value in (2, 3):
            want = 3
    return values[0], values[1], pos


def nonce(sender: int, seq: int) -> bytes:
    return bytes([sender]) + bytes(6) + seq.to_bytes(6, "big")


def aad(mode: str, sender: int, fingerprint: bytes, header: bytes, words: bytes) -> bytes:
    """The authenticated data: `words` is W and X as sent."""
    if len(fingerprint) > 255:
        raise ValueError("a schema fingerprint longer than 255 bytes")
    return bytes([VERSION, MODE_CODE[mode], sender, len(fingerprint)]) + fingerprint + header + words


def word(sender: int, seq: int, sync: Sync | None) -> bytes:
    """W, and X when `sync`."""
    if not 0 <= sender <= MAX_SENDER:
        raise ValueError(f"sender id {sender} out of range 0..{MAX_SENDER}")
    if not 0 <= seq <= MAX_SEQ:
        raise ValueError(f"sequence number {seq} out of range 0..{MAX_SEQ}")
    w = (sender << 12) | (LONG_FLAG if sync else 0) | (seq & PARTIAL_MASK)
    out = w.to_bytes(2, "big")
    if sync is None:
        return out
    if len(sync.epoch) != EPOCH_BYTES or not 0 <= sync.time < 1 << (8 * TIME_BYTES):
        raise ValueError(f"a sync word holds a {EPOCH_BYTES}-byte epoch and a 24-bit time")
    return (out + (seq >> PARTIAL_BITS).to_bytes(HIGH_BYTES, "big") + sync.epoch
            + sync.time.to_bytes(TIME_BYTES, "big"))


def seal(aead: AESCCM, mode: str, sender: int, seq: int, payload: bytes,
         fingerprint: bytes = b"", sync: Sync | None = None) -> bytes:
    """The protected form of an unprotected payload (H + fields), under the working key of
    the epoch `aead` was made for."""
    _, _, n = header_length(payload)
    header, fields = payload[:n], payload[n:]
    words = word(sender, seq, sync)
    a = aad(mode, sender, fingerprint, header, words)
    if mode == ENCRYPT:
        sealed = aead.encrypt(nonce(sender, seq), fields, a)          # ciphertext + tag
    elif mode == SIGN:
        sealed = fields + aead.encrypt(nonce(sender, seq), b"", a + fields)  # tag only
    else:
        raise ValueError(f"mode {mode!r} does not protect")
    return header + words + sealed


@dataclass(frozen=True)
class Parsed:
    """A protected payload taken apart, before any check."""

    kind: int
    id: int
    header: bytes
    sender: int
    partial: int           # low 11 bits of the sequence number
    high: int | None       # bits 11..42 when the frame carries a sync word, else None
    sync: Sync | None      # epoch and time of a sync word
    words: bytes           # W and X as received (authenticated)
    body: bytes            # fields or ciphertext
    tag: bytes

    def full_seq(self) -> int | None:
        return None if self.high is None else (self.high << PARTIAL_BITS) | self.partial


def parse(payload: bytes) -> Parsed:
    """Split a protected payload into its parts (MalformedError if it cannot be one)."""
    kind, ident, n = header_length(payload)
    if len(payload) < n + OVERHEAD:
        raise MalformedError(f"{len(payload)} bytes: too short for a protected payload")
    w = int.from_bytes(payload[n:n + WORD_BYTES], "big")
    pos = n + WORD_BYTES
    high = sync = None
    if w & LONG_FLAG:
        if len(payload) < n + SYNC_OVERHEAD:
            raise MalformedError(f"{len(payload)} bytes: too short for a protected sync payload")
        high = int.from_bytes(payload[pos:pos + HIGH_BYTES], "big")
        pos += HIGH_BYTES
        epoch = payload[pos:pos + EPOCH_BYTES]
        pos += EPOCH_BYTES
        sync = Sync(epoch, int.from_bytes(payload[pos:pos + TIME_BYTES], "big"))
        pos += TIME_BYTES
    return Parsed(kind, ident, payload[:n], w >> 12, w & PARTIAL_MASK, high, sync,
                  payload[n:pos], payload[pos:-TAG_BYTES], payload[-TAG_BYTES:])


def open_parsed(aead: AESCCM, mode: str, p: Parsed, seq: int, fingerprint: bytes = b"") -> bytes:
    """The unprotected payload (H + fields); raises InvalidTag when anything was changed."""
    a = aad(mode, p.sender, fingerprint, p.header, p.words)
    if mode == ENCRYPT:
        fields = aead.decrypt(nonce(p.sender, seq), p.body + p.tag, a)
    elif mode == SIGN:
        aead.decrypt(nonce(p.sender, seq), p.tag, a + p.body)
        fields = p.body
    else:
        raise ValueError(f"mode {mode!r} does not protect")
    return p.header + fields
