"""The packet envelope of wire format 2 (docs/wire-format.md section 14, docs/seams.md section 1).

A link of profile `native` or `packed` writes one frame per DESERT write, and that frame's payload
is one envelope:

    P | W | [K] | [T] | [A] | [C] | M1 M2 ... Mn | [tag]

- P (1 byte): bits 7-5 the version (`010` = 2), then flags S (sealed: a tag ends the
  envelope; 8 bytes, or the link's `security: {tag_bytes}`), K, T, A, C (which optional parts
  follow);
- W (2 bytes, big-endian): sender id (bits 15-12), packet number mod 4096 (bits 11-0);
- K (10 bytes): the sender's epoch (6 bytes) and packet number bits 12-43 (4 bytes, big-endian);
- T (3 bytes): the sender's clock at sealing, 24-bit count of 1/32 s, big-endian;
- A and C (1 + L bytes each): L, then L opaque bytes (acknowledgements; security control);
- messages: each `H [len] body`. H is one byte for the common case:

      bit 7     L: a length byte follows H (set on every message but the last)
      bits 6-5  kind: 00 topic (0), 01 request (2), 10 response (3), 11 escape
      bits 4-0  id 1..31; 0: the id follows in one byte (32..255)

  With kind escape (`11`), bits 4-0 are 0 and two bytes follow: the kind (any but 0, 2, 3), then
  the id (1..255); bits 4-0 of 1 (H = 0x61) make a fragment message, no id: its body is
  uwgen.runtime.wire.fragment's compact fragment. The last message has no length: its body is what
  remains before the tag.

This module is pure: bytes in, an `Envelope` out (or one `EnvelopeError`), and back. It interprets
P, W and the messages; K, T, A, C and the tag are carried as values and bytes for their owners
(security, commands). How long a tag is, is not in the bytes: `decode` is told it (`tag_len`,
the link's setting, default 8). Every envelope has exactly one encoding: `decode` refuses what `encode`
would never write (a length on the last message, an id escape for an id that fits H, ...), so
`encode(decode(b)) == b` for every accepted `b`.

The transition helpers `from_v1` / `to_v1` turn a wire format 1 payload (CBOR kind and id items,
then the rest) into a message and back, so generated codecs need not change.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.manifest.model import DEFAULT_TAG_BYTES, TAG_BYTES

VERSION = 2
VERSION_MASK = 0xE0
VERSION_BITS = VERSION << 5          # 0x40
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
MAX_BODY = 255              # a message's length byte

H_LENGTH = 0x80
KIND_CODES = {0: 0b00, 2: 0b01, 3: 0b10}
CODE_KINDS = {v: k for k, v in KIND_CODES.items()}
ESCAPE_CODE = 0b11
SHORT_IDS = 31              # ids 1..31 fit in H
FRAGMENT = 0x100            # Message.kind of a fragment message (never a wire kind; its id is 0)
H_FRAGMENT = (ESCAPE_CODE << 5) | 1     # 0x61: H of a fragment message (fragment.py has its body)


class EnvelopeError(ValueError):
    """Bytes that are not an envelope, or an envelope that cannot be encoded.

    `version` is the version bits of P when they are not 2 (e.g. 0 for a wire format 1 payload,
    whose first byte is a CBOR kind `00`, `02` or `03`), else None.
    """

    def __init__(self, message: str, version: int | None = None):
        super().__init__(message)
        self.version = version


@dataclass(frozen=True)
class Message:
    """One message of an envelope: kind (0 topic, 2 request, 3 response, or an escaped kind),
    manifest id (1..255) and body (the payload after its kind and id)."""

    kind: int
    id: int
    body: bytes

    def header(self) -> bytes:
        """H (and the escape bytes), without the length flag."""
        if self.kind == FRAGMENT:
            if self.id != 0:
                raise EnvelopeError(f"a fragment message has no id, got {self.id}")
            return bytes((H_FRAGMENT,))
        if not 1 <= self.id <= 255:
            raise EnvelopeError(f"message id must be 1..255, got {self.id}")
        code = KIND_CODES.get(self.kind)
        if code is None:
            if not 0 <= self.kind <= 255:
                raise EnvelopeError(f"message kind must be 0..255, got {self.kind}")
            return bytes((ESCAPE_CODE << 5, self.kind, self.id))
        if self.id <= SHORT_IDS:
            return bytes(((code << 5) | self.id,))
        return bytes((code << 5, self.id))

    def size(self, last: bool = True) -> int:
        """Bytes this message takes in an envelope (plus its length byte unless it is the last)."""
        return len(self.header()) + len(self.body) + (0 if last else 1)


def is_fragment_message(m: Message, fragment_id: int | None) -> bool:
    """Whether `m` carries a fragment: a fragment message (H 61), or a topic message on the
    manifest's `fragment_id` (fragments in wire format 1's form, which a receiver still takes).
    What a fragment carries is known only once reassembled: a seal that decides per id treats
    it like the most protected id."""
    return m.kind == FRAGMENT or (fragment_id is not None and m.kind == 0 and m.id == fragment_id)


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


def encode_messages(messages: tuple[Message, ...] | list[Message]) -> bytes:
    out = bytearray()
    last = len(messages) - 1
    for i, m in enumerate(messages):
        h = bytearray(m.header())
        if i < last:
            if len(m.body) > MAX_BODY:
                raise EnvelopeError(f"message body of {len(m.body)} bytes: at most {MAX_BODY} "
                                    "unless it is the last")
            h[0] |= H_LENGTH
            h.append(len(m.body))
        out += h
        out += m.body
    return bytes(out)


def messages_size(sizes: list[int]) -> int:
    """Bytes of messages whose sizes (header + body, no length byte) are given, in one envelope."""
    return sum(sizes) + max(0, len(sizes) - 1)


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
            raise EnvelopeError(f"not a wire format 2 envelope (version bits {b[0] >> 5})",
                                version=b[0] >> 5)
        raise EnvelopeError(f"envelope of {n} bytes: at least {HEAD} (P and W)")
    if n > MAX_PAYLOAD:
        raise EnvelopeError(f"envelope of {n} bytes: a frame holds at most {MAX_PAYLOAD}")
    p = b[0]
    if p & VERSION_MASK != VERSION_BITS:
        raise EnvelopeError(f"not a wire format 2 envelope (version bits {p >> 5})", version=p >> 5)
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
    messages = []
    while pos < end:
        m, pos = _message(b, pos, end, len(messages))
        messages.append(m)
    return Envelope(sender=w >> 12, number=w & (NUMBER_MOD - 1), messages=tuple(messages),
                    sync=sync, time=time, ack=ack, control=control,
                    tag=b[end:] if p & FLAG_S else None)


def _part(b: bytes, pos: int, end: int, what: str) -> tuple[bytes, int]:
    if pos >= end:
        raise EnvelopeError(f"envelope ends before the length of its {what} part")
    size = b[pos]
    if pos + 1 + size > end:
        raise EnvelopeError(f"{what} part of {size} bytes does not fit the envelope")
    return b[pos + 1:pos + 1 + size], pos + 1 + size


def _message(b: bytes, pos: int, end: int, index: int) -> tuple[Message, int]:
    h = b[pos]
    pos += 1
    code = (h >> 5) & 0b11
    low = h & 0x1F
    if code == ESCAPE_CODE and low == 1:
        kind, ident = FRAGMENT, 0
    elif code == ESCAPE_CODE:
        if low:
            raise EnvelopeError(f"message {index}: escape code with id bits {low} (0: an escaped "
                                "kind, 1: a fragment; others reserved)")
        if pos + 2 > end:
            raise EnvelopeError(f"message {index}: envelope ends inside its escaped header")
        kind, ident = b[pos], b[pos + 1]
        pos += 2
        if kind in KIND_CODES:
            raise EnvelopeError(f"message {index}: kind {kind} escaped although H carries it")
        if ident == 0:
            raise EnvelopeError(f"message {index}: id 0")
    else:
        kind = CODE_KINDS[code]
        if low:
            ident = low
        else:
            if pos >= end:
                raise EnvelopeError(f"message {index}: envelope ends before its id")
            ident = b[pos]
            pos += 1
            if ident <= SHORT_IDS:
                raise EnvelopeError(f"message {index}: id {ident} escaped although H carries it")
    if h & H_LENGTH:
        if pos >= end:
            raise EnvelopeError(f"message {index}: envelope ends before its length")
        size = b[pos]
        pos += 1
        if pos + size > end:
            raise EnvelopeError(f"message {index}: body of {size} bytes does not fit the envelope")
        if pos + size == end:
            raise EnvelopeError(f"message {index}: the last message carries a length")
        return Message(kind, ident, b[pos:pos + size]), pos + size
    return Message(kind, ident, b[pos:end]), end


# -- transition: wire format 1 payloads (CBOR kind and id items first) ---------------------------

def from_v1(payload: bytes | bytearray | memoryview) -> Message:
    """The message of a wire format 1 payload: its CBOR kind and id items become H, the rest is
    the body. EnvelopeError when the payload does not start with a kind below 24 and an id."""
    b = bytes(payload)
    if b[:1] == bytes((H_FRAGMENT,)):        # a fragment message (wire format 2's own form)
        return Message(FRAGMENT, 0, b[1:])
    if len(b) < 2 or b[0] >= 24:
        raise EnvelopeError("payload does not start with a CBOR kind below 24")
    kind = b[0]
    if b[1] < 24:
        ident, rest = b[1], 2
    elif b[1] == 0x18 and len(b) >= 3 and b[2] >= 24:
        ident, rest = b[2], 3
    else:
        raise EnvelopeError("payload's id is not a CBOR unsigned 1..255 in its shortest form")
    if ident == 0:
        raise EnvelopeError("payload's id is 0")
    return Message(kind, ident, b[rest:])


def to_v1(message: Message) -> bytes:
    """The wire format 1 payload of a message: CBOR kind and id, then the body. A fragment
    message stays as it is in the envelope (H 0x61, then its body): only fragment.py reads it."""
    if message.kind == FRAGMENT:
        return bytes((H_FRAGMENT,)) + message.body
    k, i = message.kind, message.id
    head = bytes((k,)) if k < 24 else bytes((0x18, k))
    head += bytes((i,)) if i < 24 else bytes((0x18, i))
    return head + message.body


def v1_message_size(payload: bytes, last: bool = False) -> int:
    """Bytes the wire format 1 `payload` takes as a message of an envelope."""
    return from_v1(payload).size(last)


def _cbor_uint_end(b: bytes, pos: int) -> int:
    """Where the CBOR unsigned integer at `pos` ends; EnvelopeError if there is none."""
    if pos >= len(b) or b[pos] >> 5 != 0 or (b[pos] & 0x1F) > 27:
        raise EnvelopeError("payload: expected an unsigned integer")
    info = b[pos] & 0x1F
    end = pos + 1 + (0 if info < 24 else 1 << (info - 24))
    if end > len(b):
        raise EnvelopeError("payload ends inside an unsigned integer")
    return end


def _packed_fields_at(b: bytes) -> int:
    """Where a packed payload's fields start: after kind, id and (requests, responses) the seq."""
    pos = _cbor_uint_end(b, _cbor_uint_end(b, 0))
    return _cbor_uint_end(b, pos) if b[0] in (2, 3) else pos


def strip_packed_head(payload: bytes) -> bytes:
    """A profile-`packed` wire format 1 payload without the head of its fields' byte string: in
    wire format 2 the message's length (or the envelope's end) already says how long it is."""
    b = bytes(payload)
    pos = _packed_fields_at(b)
    if pos >= len(b) or b[pos] >> 5 != 2 or (b[pos] & 0x1F) > 25:
        raise EnvelopeError("packed payload: expected the fields' byte string")
    info = b[pos] & 0x1F
    start = pos + 1 + (0 if info < 24 else 1 << (info - 24))
    size = info if info < 24 else int.from_bytes(b[pos + 1:start], "big")
    if start + size != len(b):
        raise EnvelopeError("packed payload: the byte string is not all that follows the header")
    return b[:pos] + b[start:]


def add_packed_head(payload: bytes) -> bytes:
    """The inverse of `strip_packed_head`: the fields become one CBOR byte string again."""
    b = bytes(payload)
    pos = _packed_fields_at(b)
    n = len(b) - pos
    head = bytes((0x40 | n,)) if n < 24 else (bytes((0x58, n)) if n < 256
                                              else b"\x59" + n.to_bytes(2, "big"))
    return b[:pos] + head + b[pos:]
