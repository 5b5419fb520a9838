"""Wire format 1 payloads as envelope messages, and back (docs/wire-format.md section 14).

A wire format 1 payload starts with CBOR kind and id items; in an envelope those become the
message's header H and the rest is its body, so generated codecs need not change. A
profile-`packed` payload also loses its fields' byte-string head (`strip_packed_head`).
uwgen.runtime.wire.envelope re-exports these.
"""
from __future__ import annotations

from uwgen.runtime.wire.messages import (CUT_TAIL, FRAGMENT, H_CUT_TAIL, H_FRAGMENT, EnvelopeError,
                                         Message)


def from_v1(payload: bytes | bytearray | memoryview) -> Message:
    """The message of a wire format 1 payload: its CBOR kind and id items become H, the rest is
    the body. EnvelopeError when the payload does not start with a kind below 24 and an id."""
    b = bytes(payload)
    if b[:1] == bytes((H_FRAGMENT,)):        # a fragment message (the envelope's own form)
        return Message(FRAGMENT, 0, b[1:])
    if b[:1] == bytes((H_CUT_TAIL,)):        # a cut tail, as the packer tells its hooks of it
        return Message(CUT_TAIL, 0, b[1:])
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
    message stays as it is in the envelope (H 0x61, then its body): only fragment.py reads it;
    so does a cut tail (H 0x64), which only the packer's hooks see (they measure packets)."""
    if message.kind == FRAGMENT:
        return bytes((H_FRAGMENT,)) + message.body
    if message.kind == CUT_TAIL:             # (H 0x64, then its body: the packer's hooks count it)
        return bytes((H_CUT_TAIL,)) + message.body
    if message.cut:
        raise EnvelopeError("a cut head is no payload until it is joined")
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
