"""Messages of an envelope (docs/wire-format.md section 14): `H [len] body`, and runs.

H is one byte for the common case:

    bit 7     L: a length byte follows H (set on every message but the last)
    bits 6-5  kind: 00 topic (0), 01 request (2), 10 response (3), 11 escape
    bits 4-0  id 1..31; 0: the id follows in one byte (32..255)

With kind escape (`11`), bits 4-0 are 0 and two bytes follow: the kind (any but 0, 2, 3), then
the id (1..255); bits 4-0 of 1 (H = 0x61) make a fragment message, no id: its body is
uwgen.runtime.wire.fragment's compact fragment. The last message has no length: its body is what
remains before the tag.

**Runs** (wire format 3): three or more messages of one kind and id whose bodies have the same
length share one head, `62 | H' | n | [b] | body 1 .. body n` (H = 0x62, with L 0xE2): H' is
their header without L (1 to 3 bytes), n their count (3..255), b the length of each body (only
when L: not the last block of the envelope; otherwise the bodies share what remains). A run
costs 3 bytes (4 with b) for all its messages where each message alone costs its H and a length
byte: packed Twists of 4 bytes go 4 + 3/n bytes each instead of 6. The encoder groups: consecutive
messages of one entry (kind and id) whose bodies have one length form a block, placed where its
first message appears (a fragment is its own block); a block of 3 or more is a run (255 at most:
a longer one is cut), smaller ones are single messages. Each entry's order is kept, which is all
a receiver relies on (a FIFO topic, fragments of a transfer, numbers of a reliable entry). Every envelope has one encoding: the
decoder refuses bytes that the encoder would have grouped otherwise.

**Cut messages** (wire format 4, docs/wire-format.md section 14.2): a message that does not fit
the rest of a packet may be cut in two. Its first part ends the packet as a **cut head**,
`63 | H' | part` (always the last message: no length), H' its header without L; the rest starts
the same sender's next packet as a **cut tail**, `64 | [len] | part` (H 0x64, 0xE4 with L;
always the first message; no id: the head said it). A `Message` of a cut head has kind
`CUT_HEAD | kind` and the message's id; a cut tail has kind `CUT_TAIL` and id 0
(uwgen.runtime.wire.cuts joins them).
"""
from __future__ import annotations

from dataclasses import dataclass

MAX_BODY = 255              # a message's length byte
H_LENGTH = 0x80
KIND_CODES = {0: 0b00, 2: 0b01, 3: 0b10}
CODE_KINDS = {v: k for k, v in KIND_CODES.items()}
ESCAPE_CODE = 0b11
SHORT_IDS = 31              # ids 1..31 fit in H
FRAGMENT = 0x100            # Message.kind of a fragment message (never a wire kind; its id is 0)
H_FRAGMENT = (ESCAPE_CODE << 5) | 1     # 0x61: H of a fragment message (fragment.py has its body)
H_RUN = (ESCAPE_CODE << 5) | 2          # 0x62: H of a run of messages that share one head
H_CUT_HEAD = (ESCAPE_CODE << 5) | 3     # 0x63: the first part of a cut message (last, no length)
H_CUT_TAIL = (ESCAPE_CODE << 5) | 4     # 0x64: the rest of a cut message (first; no id)
CUT_HEAD = 0x200            # Message.kind of a cut head: CUT_HEAD | the message's kind
CUT_TAIL = 0x400            # Message.kind of a cut tail (its id is 0)
RUN_MIN = 3                 # fewer messages cost no more alone (2 singles = a run of 2)
RUN_MAX = 255


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

    @property
    def cut(self) -> bool:
        """Whether this is a part of a cut message (a cut head or a cut tail)."""
        return bool(self.kind & (CUT_HEAD | CUT_TAIL))

    def header(self) -> bytes:
        """H (and the escape bytes), without the length flag."""
        if self.kind in (FRAGMENT, CUT_TAIL):
            if self.id != 0:
                raise EnvelopeError(f"a fragment or cut tail has no id, got {self.id}")
            return bytes((H_FRAGMENT if self.kind == FRAGMENT else H_CUT_TAIL,))
        if self.kind & CUT_HEAD:
            return bytes((H_CUT_HEAD,)) + Message(self.kind & ~CUT_HEAD, self.id, b"").header()
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
    """Whether `m` carries a part of a message whose id it does not say: a fragment message
    (H 61), a topic message on the manifest's `fragment_id` (fragments in wire format 1's form,
    which a receiver still takes), or a cut tail (H 64). What such a part carries is known only
    once reassembled or joined: a seal that decides per id treats it like the most protected
    id (a cut head says its id and is treated as that id)."""
    return (m.kind in (FRAGMENT, CUT_TAIL)
            or (fragment_id is not None and m.kind == 0 and m.id == fragment_id))



def blocks(messages: tuple[Message, ...] | list[Message]) -> list[list[Message]]:
    """The envelope's blocks, in the encoder's order: consecutive messages of one entry (kind
    and id) with bodies of one length form a block, placed where its first message appears
    among the blocks (a message of another length starts the entry's next block; runs are
    cut at RUN_MAX); a fragment and a part of a cut message are blocks of their own, a cut
    tail first and a cut head last. Each entry's order is kept."""
    out: list[list[Message]] = []
    current: dict[tuple[int, int], list[Message]] = {}
    tail = [[m] for m in messages if m.kind == CUT_TAIL]
    head = [[m] for m in messages if m.kind & CUT_HEAD]
    for m in messages:
        if m.cut:
            continue
        if m.kind == FRAGMENT:
            out.append([m])
            continue
        entry = (m.kind, m.id)
        block = current.get(entry)
        if block is None or len(block[0].body) != len(m.body) or len(block) >= RUN_MAX:
            block = current[entry] = []
            out.append(block)
        block.append(m)
    if len(tail) > 1 or len(head) > 1:
        raise EnvelopeError("an envelope carries at most one cut tail and one cut head")
    return tail + out + head


def ordered(messages: tuple[Message, ...] | list[Message]) -> tuple[Message, ...]:
    """`messages` in the order the envelope carries them (and a receiver decodes them)."""
    return tuple(m for block in blocks(messages) for m in block)


def encode_messages(messages: tuple[Message, ...] | list[Message]) -> bytes:
    """The messages' bytes, in blocks (`blocks`): runs of RUN_MIN or more, singles otherwise."""
    out = bytearray()
    parts = blocks(messages)
    for i, block in enumerate(parts):
        last = i == len(parts) - 1
        if len(block) >= RUN_MIN:
            m = block[0]
            if len(m.body) > MAX_BODY:
                raise EnvelopeError(f"bodies of {len(m.body)} bytes in a run: at most {MAX_BODY}")
            out.append(H_RUN | (0 if last else H_LENGTH))
            out += m.header()
            out.append(len(block))
            if not last:
                out.append(len(m.body))
            for r in block:
                out += r.body
            continue
        for j, m in enumerate(block):
            h = bytearray(m.header())
            if not (last and j == len(block) - 1):
                if len(m.body) > MAX_BODY:
                    raise EnvelopeError(f"message body of {len(m.body)} bytes: at most {MAX_BODY} "
                                        "unless it is the last")
                h[0] |= H_LENGTH
                h.append(len(m.body))
            out += h
            out += m.body
    return bytes(out)


def messages_size(sizes: list[int]) -> int:
    """Bytes of single messages whose sizes (header + body, no length byte) are given."""
    return sum(sizes) + max(0, len(sizes) - 1)


def decode_messages(b: bytes, pos: int, end: int) -> tuple[Message, ...]:
    """The messages in b[pos:end]; EnvelopeError unless they are in their one encoding (the
    blocks `encode_messages` would write for them)."""
    start = pos
    out: list[Message] = []
    while pos < end:
        if b[pos] & 0x7F == H_RUN:
            pos = _run(b, pos, end, out)
        elif b[pos] & 0x7F in (H_CUT_HEAD, H_CUT_TAIL):
            m, pos = _cut(b, pos, end, len(out))
            out.append(m)
        else:
            m, pos = _message(b, pos, end, len(out))
            out.append(m)
    if encode_messages(out) != b[start:end]:
        raise EnvelopeError("messages not in their one encoding (blocks of one kind, id and "
                            "body length, in order of first appearance; runs of 3 or more; "
                            "a cut tail first, a cut head last)")
    return tuple(out)


def _cut(b: bytes, pos: int, end: int, index: int) -> tuple[Message, int]:
    """A cut head (`63 H' part`, the last message) or a cut tail (`64 [len] part`, the first);
    each part at least one byte."""
    h = b[pos]
    pos += 1
    if h & 0x7F == H_CUT_TAIL:
        if index:
            raise EnvelopeError(f"message {index}: a cut tail is always the first message")
        if h & H_LENGTH:
            if pos >= end:
                raise EnvelopeError(f"message {index}: envelope ends before its length")
            size = b[pos]
            pos += 1
            if pos + size >= end:
                raise EnvelopeError(f"message {index}: a cut tail of {size} bytes with a length "
                                    "must be followed by another message")
        else:
            size = end - pos
        if not size:
            raise EnvelopeError(f"message {index}: a cut tail of no bytes")
        return Message(CUT_TAIL, 0, b[pos:pos + size]), pos + size
    if h & H_LENGTH:
        raise EnvelopeError(f"message {index}: a cut head is the last message (no length)")
    if pos >= end or b[pos] & H_LENGTH or b[pos] in (H_FRAGMENT, H_RUN, H_CUT_HEAD, H_CUT_TAIL):
        raise EnvelopeError(f"message {index}: a cut head's header is not a message's")
    kind, ident, pos = _header(b, pos, end, index)
    if pos >= end:
        raise EnvelopeError(f"message {index}: a cut head of no bytes")
    return Message(CUT_HEAD | kind, ident, b[pos:end]), end


def _run(b: bytes, pos: int, end: int, out: list[Message]) -> int:
    index = len(out)
    with_length = bool(b[pos] & H_LENGTH)
    pos += 1
    if pos >= end:
        raise EnvelopeError(f"message {index}: envelope ends inside a run's head")
    if b[pos] & H_LENGTH or b[pos] in (H_FRAGMENT, H_RUN, H_CUT_HEAD, H_CUT_TAIL):
        raise EnvelopeError(f"message {index}: a run's header {b[pos]:02X} is not a message's")
    kind, ident, pos = _header(b, pos, end, index)
    if pos >= end:
        raise EnvelopeError(f"message {index}: envelope ends before a run's count")
    n = b[pos]
    pos += 1
    if not RUN_MIN <= n:
        raise EnvelopeError(f"message {index}: a run of {n} messages (at least {RUN_MIN})")
    if with_length:
        if pos >= end:
            raise EnvelopeError(f"message {index}: envelope ends before a run's body length")
        size = b[pos]
        pos += 1
        if pos + n * size >= end:
            raise EnvelopeError(f"message {index}: a run of {n} x {size} bytes does not fit "
                                "before the envelope's last message")
    else:
        if (end - pos) % n:
            raise EnvelopeError(f"message {index}: the last run's {end - pos} bytes do not "
                                f"share out among its {n} messages")
        size = (end - pos) // n
    for _ in range(n):
        out.append(Message(kind, ident, b[pos:pos + size]))
        pos += size
    return pos


def _header(b: bytes, pos: int, end: int, index: int) -> tuple[int, int, int]:
    """Kind and id of the header at `pos` (its L bit aside), and where it ends."""
    h = b[pos]
    pos += 1
    code = (h >> 5) & 0b11
    low = h & 0x1F
    if code == ESCAPE_CODE and low == 1:
        return FRAGMENT, 0, pos
    if code == ESCAPE_CODE:
        if low:
            raise EnvelopeError(f"message {index}: escape code with id bits {low} (0: an escaped "
                                "kind, 1: a fragment, 2: a run, 3 and 4: a cut head and tail "
                                "where they may be; others reserved)")
        if pos + 2 > end:
            raise EnvelopeError(f"message {index}: envelope ends inside its escaped header")
        kind, ident = b[pos], b[pos + 1]
        if kind in KIND_CODES:
            raise EnvelopeError(f"message {index}: kind {kind} escaped although H carries it")
        if ident == 0:
            raise EnvelopeError(f"message {index}: id 0")
        return kind, ident, pos + 2
    kind = CODE_KINDS[code]
    if low:
        return kind, low, pos
    if pos >= end:
        raise EnvelopeError(f"message {index}: envelope ends before its id")
    ident = b[pos]
    if ident <= SHORT_IDS:
        raise EnvelopeError(f"message {index}: id {ident} escaped although H carries it")
    return kind, ident, pos + 1


def _message(b: bytes, pos: int, end: int, index: int) -> tuple[Message, int]:
    with_length = b[pos] & H_LENGTH
    kind, ident, pos = _header(b, pos, end, index)
    if with_length:
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
