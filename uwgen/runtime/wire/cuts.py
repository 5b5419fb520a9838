"""Cut messages: cutting one to end a packet, and joining its parts again (docs/wire-format.md
section 14.2). Pure: envelopes and messages in, messages out.

A message that does not fit the rest of a packet may be cut: its first part ends that packet
as a cut head (`Message(CUT_HEAD | kind, id, part)`, always the envelope's last message), the
rest starts the same sender's next packet as a cut tail (`Message(CUT_TAIL, 0, part)`, always
the first). A receiver joins a tail only to the head of the same sender's packet number minus
one, in the same epoch, both admitted (the caller feeds only envelopes that decoded and, on a
sealed link, whose tag was checked). Anything else is an orphan, counted `cut_orphan` and
dropped: the message is lost whole, as when either packet is lost, never delivered in part.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.runtime.wire.envelope import (CUT_HEAD, CUT_TAIL, NUMBER_MOD, Envelope, EnvelopeError,
                                         Message)

TAIL_HEAD = 2      # a cut tail's H and length byte, as a packet's room counts them


def cut(message: Message, first: int) -> tuple[Message, Message]:
    """`message` as its cut head (the first `first` bytes of its body) and its cut tail (the
    rest); each part must hold at least one byte."""
    if message.cut or message.kind & ~0xFF:
        raise EnvelopeError("only a whole topic, request or response message may be cut")
    if not 0 < first < len(message.body):
        raise EnvelopeError(f"a cut after {first} of {len(message.body)} bytes leaves a part empty")
    return (Message(CUT_HEAD | message.kind, message.id, message.body[:first]),
            Message(CUT_TAIL, 0, message.body[first:]))


@dataclass
class _Head:
    number: int             # the packet number (mod 4096) that carried it
    epoch: bytes | None     # the sender's epoch as last seen in K (None: none seen)
    message: Message


class Joiner:
    """Joins cut tails to their heads, per sender; counts what cannot be joined."""

    def __init__(self) -> None:
        self._heads: dict[int, _Head] = {}
        self._epochs: dict[int, bytes] = {}
        self.joined = 0
        self.orphans = 0

    def feed(self, envelope: Envelope) -> list[Message]:
        """The messages of an admitted envelope with its cut parts resolved: a tail joined to
        the head of the sender's previous packet comes first as the whole message; the head
        this packet ends with is held for the sender's next packet."""
        sender = envelope.sender
        if envelope.sync is not None:
            self._epochs[sender] = bytes(envelope.sync.epoch)
        epoch = self._epochs.get(sender)
        held = self._heads.pop(sender, None)
        out: list[Message] = []
        for m in envelope.messages:
            if m.kind == CUT_TAIL:
                if (held is not None and held.epoch == epoch
                        and (held.number + 1) % NUMBER_MOD == envelope.number):
                    h = held.message
                    out.append(Message(h.kind & ~CUT_HEAD, h.id, h.body + m.body))
                    self.joined += 1
                else:
                    self.orphans += 1        # its head was lost (or came from another epoch)
                held = None
            elif m.kind & CUT_HEAD:
                self._heads[sender] = _Head(envelope.number, epoch, m)
            else:
                out.append(m)
        if held is not None:
            self.orphans += 1                # the packet after its head began without its tail
        return out

    @property
    def pending(self) -> int:
        """Heads waiting for their sender's next packet."""
        return len(self._heads)
