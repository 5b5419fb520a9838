"""The per-packet seal of wire format 2 (docs/wire-format.md section 12.2): pure functions.

One AES-CCM tag (8 bytes) per envelope, under the working key of (sender, epoch) of section 12
(`keys.working_key`), with the nonce of section 12 (sender id, 6 zero bytes, the packet number
within its epoch, 6 bytes big-endian). The envelope's structure stays readable (P, W, the
optional parts, every message's H, escape and length bytes): a receiver can tell the ids of the
messages, and so their modes and fingerprints, before it checks anything. Then

- plaintext = the bodies of the messages whose id is `encrypt`, one after the other (a
  fragment message, `envelope.is_fragment_message`, counts as `encrypt` when the network
  encrypts any id: what it carries is not known until reassembly); on the wire each such body is replaced by its ciphertext, byte for
  byte the same length (AES-CCM is a counter mode);
- aad = `03` (this seal's version; the per-payload seal's aad starts `02`), P W K T A C as
  sent (P with S set), then every message as sent with the encrypted bodies left out, then, per
  message, the length of its id's schema fingerprint (1 byte) and the fingerprint.

So one packet may mix `encrypt`, `sign` and `off` messages under one tag; every byte of it is
authenticated: the sync part (K) and the time (T), the acknowledgements (A) and the control
part (C) included; what a receiver's manifest protects differently (another mode, another
schema) fails the tag.
"""
from __future__ import annotations

from collections.abc import Callable
from cryptography.hazmat.primitives.ciphers.aead import AESCCM

from uwgen.runtime.wire import envelope as env
from uwgen.security import wire

SEAL_VERSION = 3
ENCRYPT = wire.ENCRYPT

__all__ = ["SEAL_VERSION", "aad", "seal", "open_envelope", "encrypted_flags"]


def encrypted_flags(messages, encrypts: Callable[[env.Message], bool]) -> list[bool]:
    return [encrypts(m) for m in messages]


def _heads(messages) -> list[bytes]:
    """Each message's bytes before its body as sent: H (and the id or kind escape), then the
    length byte on every message but the last."""
    out = []
    last = len(messages) - 1
    for i, m in enumerate(messages):
        h = bytearray(m.header())
        if i < last:
            h[0] |= env.H_LENGTH
            h.append(len(m.body))
        out.append(bytes(h))
    return out


def aad(head: bytes, messages, flags: list[bool], fingerprint: Callable[[int], bytes]) -> bytes:
    """The authenticated data of a packet whose bytes before the messages are `head` (P with S
    set, W, K, T, A, C); `flags[i]`: message i's body is encrypted (left out here)."""
    out = bytearray((SEAL_VERSION,))
    out += head
    for h, m, enc in zip(_heads(messages), messages, flags):
        out += h
        if not enc:
            out += m.body
    for m in messages:
        fp = fingerprint(m.id)
        if len(fp) > 255:
            raise env.EnvelopeError(f"id {m.id}: a schema fingerprint longer than 255 bytes")
        out.append(len(fp))
        out += fp
    return bytes(out)


def _head(envelope: env.Envelope) -> bytes:
    """P (S set), W and the optional parts of `envelope` as they are sent sealed."""
    head = envelope.encode_head()
    return bytes((head[0] | env.FLAG_S,)) + head[1:]


def _with(e: env.Envelope, messages: tuple[env.Message, ...], tag: bytes | None) -> env.Envelope:
    return env.Envelope(e.sender, e.number, messages, e.sync, e.time, e.ack, e.control, tag)


def seal(aead: AESCCM, envelope: env.Envelope, seq: int, encrypts: Callable[[env.Message], bool],
         fingerprint: Callable[[int], bytes]) -> bytes:
    """The sealed envelope's bytes: `envelope` (unsealed, its parts set) under packet number
    `seq` of its sender's epoch (W must carry seq's low 12 bits)."""
    if envelope.number != seq % env.NUMBER_MOD:
        raise env.EnvelopeError(f"W carries packet number {envelope.number}, the seal numbered it "
                                f"{seq} (low bits {seq % env.NUMBER_MOD})")
    messages = envelope.messages
    flags = encrypted_flags(messages, encrypts)
    head = _head(envelope)
    a = aad(head, messages, flags, fingerprint)
    plain = b"".join(m.body for m, enc in zip(messages, flags) if enc)
    sealed = aead.encrypt(wire.nonce(envelope.sender, seq), plain, a)
    out = head + env.encode_messages(_swap(messages, flags, sealed[:len(plain)])) + sealed[len(plain):]
    if len(out) > env.MAX_PAYLOAD:
        raise env.EnvelopeError(f"envelope of {len(out)} bytes: a frame holds at most {env.MAX_PAYLOAD}")
    return out


def open_envelope(aead: AESCCM, envelope: env.Envelope, seq: int,
                  encrypts: Callable[[env.Message], bool],
                  fingerprint: Callable[[int], bytes]) -> env.Envelope | None:
    """The envelope with its encrypted bodies in the clear (tag kept), or None when the tag does
    not verify under `aead` and packet number `seq`."""
    messages = envelope.messages
    flags = encrypted_flags(messages, encrypts)
    try:
        a = aad(_head(envelope), messages, flags, fingerprint)
    except env.EnvelopeError:
        return None
    cipher = b"".join(m.body for m, enc in zip(messages, flags) if enc)
    try:
        plain = aead.decrypt(wire.nonce(envelope.sender, seq), cipher + envelope.tag, a)
    except wire.InvalidTag:
        return None
    return _with(envelope, _swap(messages, flags, plain), envelope.tag)


def _swap(messages, flags: list[bool], data: bytes) -> tuple[env.Message, ...]:
    """`messages` with the encrypted bodies replaced, in order, by the slices of `data`."""
    if not data:
        return tuple(messages)
    out, pos = [], 0
    for m, enc in zip(messages, flags):
        if enc:
            n = len(m.body)
            m = env.Message(m.kind, m.id, data[pos:pos + n])
            pos += n
        out.append(m)
    return tuple(out)
