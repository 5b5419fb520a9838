"""Packets of wire format 4: one envelope per DESERT write, filled from the link scheduler.

`Packer.next_packet(now)` is called by the connection when it may write; it pulls messages from
the scheduler while they fit one packet (`max_read_length` minus the frame, P, W and what the
hooks add), may end it with a cut message's head (wire-format.md 14.2), builds the envelope at
that moment (so a seal is never older than the packet), and tells the hooks which messages went
in which packet number. `Unpacker.feed(payload)` opens one received frame's envelope, joins cut
messages and returns its messages as wire format 1 payloads, for the link's fragment, security
and dispatch layers, which are unchanged.

The seams of reliability and the seal (docs/seams.md section 5) are the `PacketHooks`:

- `parts(now)` -> dict of extra `Envelope` fields (`time`, `ack`, `control`, `sync`) for the
  packet being built; `overhead` is the most bytes they and the seal add to a packet;
  `next_overhead(now)`, when given, the bytes they will add to the next packet (at most
  `overhead` but for a part that goes only now and then, as K; asked before its messages are
  picked, so a packet without a sync part holds more);
- `number()` -> the full number of the packet being built, asked once per packet after its
  messages are picked (the seal numbers packets: its session's number, docs/seams.md section 2);
  without it the packer counts from 0;
- `seal(envelope)` -> the packet's bytes (tag included); without it the envelope is sent as is;
- `open(bytes)` -> an `Envelope`, or None when the packet is dropped (counted by its owner);
  without it the bytes are decoded with `envelope.decode`;
- `sent(number, [(channel key, payload), ...], now)` after each packet is built, with the
  sender's full packet number (not reduced mod 4096);
- `received(envelope, now)` for every envelope accepted, before its messages are delivered;
  False: a repeat of a packet received, whose messages are dropped (counted `repeated_packets`).

Reliability also uses (docs/seams.md section 5, "How the two sets of hooks meet"):

- `carrying([(key, payload), ...], now, fresh)` once a packet's messages are chosen, before
  `parts` (the cut tail a packet starts with is among them, as `64 body`: it takes room, but
  it is in no `sent` list: its message went with the packet of its head); `fresh`: some are
  not copies (a MAC keeps a turn going for fresh messages only);
- `resend(now, room)` -> a (key, payload) to send again, at most `room` bytes as counted by
  `message_measure`, or None: served before the scheduler's messages;
- `copy(now, room, fresh)` -> the same for a copy of a message not acknowledged yet, asked
  only for the room a packet that leaves anyway has left after its messages (never
  displacing one); `fresh`: it carries fresh messages (else it leaves for `ack_only`);
- `ack_only(now)` -> True when a packet must leave even without messages (an acknowledgement
  is due): the packer then builds one with only the hooks' parts;
- `next_time(now)` -> when one of the above will next want a packet (None: never), so the
  connection wakes up for it;
- `stamp(key, payload, born, now)` -> the payload with its reliability head, as the scheduler
  takes it to be sent (`born`: its publication time); `head_room(key)` the most bytes it adds;
- `admit(payload, now)` -> the payload without its head, or None (a duplicate, a stale
  command: counted by the hook), for every whole payload received;
- `stats()` -> a JSON-able dict the link reports (e.g. the per-entry ledger).

Heads sized per packet (docs/seams.md section 9): `next_overhead(now)` is what the hooks add
to *this* packet whatever it carries (an A part when an ack is due, the seal's tag and sync),
and `part_room(key)` what a message of channel `key` brings into its packet's parts the first
time one is picked (T, for an entry with a max age): the packer charges it once a packet,
so nothing is reserved by constant.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uwgen.runtime.link.filling import added, cut_point
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.cuts import Joiner, cut
from uwgen.runtime.wire.framing import MAX_PAYLOAD, SHORT_OVERHEAD
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link.packets")
OLD_ENVELOPES = (2, 3)      # envelope versions of earlier builds: counted version_N, logged once
OLD_SHORT_BITS = 3 << 5     # P of wire format 3, the first to use the short frame

PACKET_COUNTERS = ("packets_sent", "messages_sent", "packets_received", "messages_received",
                   "bad_envelopes", "version_1", "version_2", "version_3", "unknown_kind",
                   "refused_payloads", "opened_none", "ack_only_sent",
                   "cut_sent", "cut_dropped", "cut_joined", "cut_orphan", "repeated_packets")


def envelope_room(max_read_length: int, overhead: int = 0) -> int:
    """Bytes of messages one packet holds: the short frame's payload (wire format 3) minus P, W
    and `overhead`, plus one (the last message has no length byte, and `message_measure`
    counts one per message)."""
    return (min(max_read_length, MAX_PAYLOAD + SHORT_OVERHEAD) - SHORT_OVERHEAD - env.HEAD
            - overhead + 1)


def envelope_check(payload: bytes) -> bool:
    """Whether `payload` decodes as an envelope (sealed, with any tag length a link may have):
    what the short frame's decoder asks of a start. One of wire format 3 is taken when it would
    decode as 4 (3 is 4 without cuts), so that the unpacker counts its sender (`version_3`)."""
    if payload and payload[0] & env.VERSION_MASK == OLD_SHORT_BITS:
        payload = bytes((payload[0] & ~env.VERSION_MASK & 0xFF | env.VERSION_BITS,)) + payload[1:]
    for tag_len in env.TAG_LENGTHS:
        try:
            env.decode(payload, tag_len)
            return True
        except env.EnvelopeError:
            if not payload[0] & env.FLAG_S:
                return False
    return False


def message_measure(payload: bytes) -> int:
    """What a wire format 1 payload costs in a packet, length byte included (see envelope_room):
    its header and body plus one length byte, as `Message.size(last=False)` counts it (the
    packer charges exactly that; counting the length byte twice here left a byte of every
    packet's tail unused)."""
    try:
        return env.v1_message_size(payload)
    except env.EnvelopeError:
        return len(payload) + 1


class Packer:
    """Builds one envelope per write from the scheduler's messages."""

    def __init__(self, scheduler: Any, *, sender: int, max_read_length: int,
                 hooks: PacketHooks | None = None, counters: Counters, name: str = "link"):
        if not 0 <= sender <= env.MAX_SENDER:
            raise ValueError(f"sender id must be 0..{env.MAX_SENDER}, got {sender}")
        self.scheduler = scheduler
        self.sender = sender
        self.hooks = hooks or PacketHooks()
        self.max_read_length = max_read_length
        self.room = envelope_room(max_read_length, self.hooks.overhead)
        self.counters = counters
        self.name = name
        self.number = 0                     # the next packet's number (full count)
        self.first: env.Message | None = None   # the cut tail the next packet starts with
        self._cut_of: int | None = None         # the packet `first` was cut at (self.number)
        self._moved = False                     # `first` is a whole message, not a tail
        self.first_key = 0                       # and its channel

    def next_packet(self, now: float) -> bytes | None:
        picked: list[tuple[int, bytes]] = []
        messages: list[env.Message] = []
        h = self.hooks
        room = self.room
        charged = 0               # bytes of parts the picked messages bring (part_room)
        if h.next_overhead is not None:
            room = envelope_room(self.max_read_length, h.next_overhead(now))
        carried: list[tuple[int, bytes]] = []   # what `carrying` is told takes room
        if self.first is not None:          # the rest of the message cut at the last packet's end
            first, self.first = self.first, None
            if first.size(last=False) <= room:
                messages.append(first)
                carried.append((self.first_key, env.to_v1(first)))
            else:
                log_count(log, logging.ERROR, self.counters.inc("cut_dropped"), "[%s] the rest "
                          "of a cut message (%d bytes) does not fit the next packet (its parts "
                          "took the room): the message is lost", self.name, len(first.body))
        encoded = len(env.encode_messages(messages))     # the messages' bytes so far
        budget = room - encoded - 1 if messages else room
        # Messages the peer lost (reliable entries) go first, then the scheduler's.
        # A message that brings a part (T) fits only with that part: the scheduler counts
        # `extra(key)` into each channel's next size; a re-sent one is offered the room less
        # the most a part may add.
        roomy = h.part_room

        def extra(key: int) -> int:
            return max(0, roomy(key) - charged) if roomy is not None else 0

        sources = [] if h.resend is None else [
            lambda room: h.resend(now, room - (max(0, env.TIME_LEN - charged) if roomy else 0))]
        sources.append(lambda room: self.scheduler.next_payload(
            now, room if messages else None, fill=True, packet=self.number,
            extra=extra if roomy is not None else None,
            measure=lambda payload: added(messages, payload, encoded)))
        def fill(source) -> None:
            nonlocal budget, charged, encoded
            while budget > 1:
                got = source(budget)
                if got is None:
                    return
                key, payload = got
                try:
                    messages.append(env.from_v1(payload))
                except env.EnvelopeError as e:
                    log_count(log, logging.ERROR, self.counters.inc("refused_payloads"),
                              "[%s] channel %d: a payload that is no message was dropped: %s",
                              self.name, key, e)
                    continue
                picked.append((key, payload))
                if h.part_room is not None:
                    more = h.part_room(key) - charged
                    if more > 0:        # a part this message brings (T): charged once a packet
                        charged += more
                # what the messages take as encoded (a message joining a run costs its body
                # alone), counted as `message_measure` counts: each with a length byte
                encoded = len(env.encode_messages(messages))
                budget = room - charged - encoded - 1

        for source in sources:
            fill(source)
        cut_at = self.number
        if messages and budget > 1:
            self._cut_last(now, messages, picked, room - charged - 1)
        cut_now = self.first is not None and self._cut_of == cut_at
        fresh = bool(carried or picked)
        leaves = fresh or (h.ack_only is not None and h.ack_only(now))
        if h.copy is not None and leaves and budget > 1 and not cut_now:
            # room left in a packet that leaves anyway (messages, or a part that must go: an
            # acknowledgement, a MAC's grant or end): copies of messages not acknowledged yet
            # and commands of this turn (wire-format.md section 15.6), after every fresh
            # message and cut head
            fill(lambda room: h.copy(now, room - (max(0, env.TIME_LEN - charged) if roomy else 0),
                                     fresh))
        if not leaves:
            return None
        if h.carrying is not None:
            h.carrying(carried + picked, now, fresh)
        number = h.number() if h.number is not None else self.number
        try:
            envelope = env.Envelope(self.sender, number % env.NUMBER_MOD, env.ordered(messages),
                                    **(h.parts(now) if h.parts is not None else {}))
            if h.shape is not None:
                envelope = h.shape(envelope)
            data = h.seal(envelope) if h.seal is not None else envelope.encode()
        except env.EnvelopeError as e:
            log_count(log, logging.ERROR, self.counters.inc("refused_payloads", len(picked)),
                      "[%s] a packet of %d message(s) could not be built and was dropped: %s",
                      self.name, len(picked), e)
            return None
        if h.sent is not None:
            h.sent(number, picked, now)
        if h.cut is not None and self.first is not None and self._cut_of == cut_at:
            h.cut(number, moved=self._moved)    # the ledger waits for the tail's packet too
        self.number = number + 1
        self.counters.inc("packets_sent")
        self.counters.inc("messages_sent", len(messages))
        if not messages:
            self.counters.inc("ack_only_sent")
        return data

    def tail_at(self, now: float) -> float | None:
        """Now when the last packet ended with a cut message's head (its tail must go next,
        even when every queue is empty), else None."""
        return now if self.first is not None else None

    def _cut_last(self, now: float, messages: list[env.Message], picked: list[tuple[int, bytes]],
                  limit: int) -> None:
        """End the packet with the head of the first message in claim order of a cuttable
        channel that brings no part (T: an entry with a max age is judged by the packet that
        carries it) and whose cut is worth it (`filling.cut_point`; `limit`: the bytes of
        messages the packet holds); its tail starts the next packet (wire format 14.2)."""
        roomy = self.hooks.part_room

        def accept(key: int, payload: bytes) -> bool:
            if roomy is not None and roomy(key):
                return False
            try:
                m = env.from_v1(payload)
            except env.EnvelopeError:
                return False
            return cut_point(messages, m, limit, self.room) is not None

        got = self.scheduler.next_payload(now, fill=False, packet=self.number, cut=accept)
        if got is None:
            return
        key, payload = got
        picked.append((key, payload))
        m = env.from_v1(payload)
        at = cut_point(messages, m, limit, self.room)
        self.first_key = key
        if at is None:        # its head changed as it was taken: it goes whole, first, next time
            self.first, self._cut_of, self._moved = m, self.number, True
            return
        self._cut_of, self._moved = self.number, False
        head, self.first = cut(m, at)
        messages.append(head)
        self.counters.inc("cut_sent")


class Unpacker:
    """Opens received envelopes; refuses (counted, logged once) what is not one."""

    def __init__(self, hooks: PacketHooks | None = None, *, counters: Counters, name: str = "link"):
        self.hooks = hooks or PacketHooks()
        self.counters = counters
        self.name = name
        self.joiner = Joiner()

    def feed(self, data: bytes, now: float) -> list[bytes]:
        """The messages of one frame's payload, as wire format 1 payloads (kind, id, body)."""
        c = self.counters
        if self.hooks.open is not None:
            try:
                envelope = self.hooks.open(data)
            except env.EnvelopeError as e:
                return self._bad(data, e)
            if envelope is None:
                c.inc("opened_none")
                return []
        else:
            try:
                envelope = env.decode(data)
            except env.EnvelopeError as e:
                return self._bad(data, e)
        c.inc("packets_received")
        if self.hooks.unshape is not None:
            envelope = self.hooks.unshape(envelope)
        if self.hooks.received is not None and self.hooks.received(envelope, now) is False:
            # a packet number already received: DESERT delivered the packet twice (an ARQ MAC
            # whose ack was lost sends it again); its messages were delivered with the first
            log_count(log, logging.INFO, c.inc("repeated_packets"),
                      "[%s] dropped a repeat of packet %d from sender %d (received before)",
                      self.name, envelope.number, envelope.sender)
            return []
        out = []
        joiner = self.joiner
        orphans = joiner.orphans
        messages = joiner.feed(envelope)
        c.inc("cut_joined", joiner.joined - c["cut_joined"])
        if joiner.orphans > orphans:
            log_count(log, logging.WARNING, c.inc("cut_orphan", joiner.orphans - orphans),
                      "[%s] dropped a part of a cut message from sender %d that cannot be "
                      "joined (the packet with its other part was lost)", self.name,
                      envelope.sender)
        for m in messages:
            if m.kind not in env.KIND_CODES and m.kind != env.FRAGMENT:
                log_count(log, logging.WARNING, c.inc("unknown_kind"),
                          "[%s] dropped a message of kind %d (id %d) from sender %d: this build "
                          "knows kinds 0, 2, 3 only", self.name, m.kind, m.id, envelope.sender)
                continue
            c.inc("messages_received")
            out.append(env.to_v1(m))
        return out

    def _bad(self, data: bytes, e: env.EnvelopeError) -> list[bytes]:
        if e.version in OLD_ENVELOPES:
            counter = f"version_{e.version}"
            if self.counters.inc(counter) == 1:
                log.error("[%s] the far side speaks wire format %d (P %02X): its packets are "
                          "refused. Rebuild it with this uwgen (wire format %d); further ones "
                          "are only counted (%s)", self.name, e.version, data[0], env.VERSION,
                          counter)
            return []
        if e.version == 0:
            if self.counters.inc("version_1") == 1:
                log.error("[%s] the far side speaks wire format 1 (its first byte %02X is a "
                          "CBOR kind, not an envelope): its frames are refused. Rebuild it with "
                          "this uwgen (wire format %d); further ones are only counted "
                          "(version_1)", self.name, data[0], env.VERSION)
            return []
        log_count(log, logging.WARNING, self.counters.inc("bad_envelopes"),
                  "[%s] dropped a packet that is not a valid envelope: %s", self.name, e)
        return []
