"""Packets of wire format 2: one envelope per DESERT write, filled from the link scheduler.

`Packer.next_packet(now)` is called by the connection when it may write; it pulls messages from
the scheduler while they fit one packet (`max_read_length` minus the frame's 4 bytes, P, W and
whatever the hooks add), builds the envelope at that moment (so a seal is never older than the
packet), and tells the hooks which messages went in which packet number. `Unpacker.feed(payload)`
opens one received frame's envelope and returns its messages as wire format 1 payloads, for the
link's fragment, security and dispatch layers, which are unchanged.

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
- `received(envelope, now)` for every envelope accepted, before its messages are delivered.

Reliability also uses (docs/seams.md section 5, "How the two sets of hooks meet"):

- `carrying([(key, payload), ...], now)` once a packet's messages are chosen, before `parts`;
- `resend(now, room)` -> a (key, payload) to send again, at most `room` bytes as counted by
  `message_measure`, or None: served before the scheduler's messages;
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

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.framing import MAX_PAYLOAD, SHORT_OVERHEAD
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link.packets")
OLD_ENVELOPES = (2, 3)      # envelope versions of earlier builds: counted version_N, logged once
OLD_SHORT_BITS = 3 << 5     # P of wire format 3, the first to use the short frame

PACKET_COUNTERS = ("packets_sent", "messages_sent", "packets_received", "messages_received",
                   "bad_envelopes", "version_1", "version_2", "version_3", "unknown_kind", "refused_payloads", "opened_none",
                   "ack_only_sent")


@dataclass
class PacketHooks:
    """What reliability (wire-format.md section 15) and the per-packet seal (section 12.2) plug
    into; all optional."""

    parts: Callable[[float], dict] | None = None
    seal: Callable[[env.Envelope], bytes] | None = None
    open: Callable[[bytes], env.Envelope | None] | None = None
    sent: Callable[[int, list[tuple[int, bytes]], float], None] | None = None
    received: Callable[[env.Envelope, float], None] | None = None
    overhead: int = 0
    next_overhead: Callable[[float], int] | None = None
    number: Callable[[], int] | None = None
    carrying: Callable[[list[tuple[int, bytes]], float], None] | None = None
    resend: Callable[[float, int], tuple[int, bytes] | None] | None = None
    ack_only: Callable[[float], bool] | None = None
    next_time: Callable[[float], float | None] | None = None
    stamp: Callable[[int, bytes, float, float], bytes] | None = None
    head_room: Callable[[int], int] | None = None
    part_room: Callable[[int], int] | None = None
    admit: Callable[[bytes, float], bytes | None] | None = None
    stats: Callable[[], dict] | None = None
    # the envelope as it leaves, before the seal, and as it arrives, after the seal's check
    # (one age item a packet left out, wire-format.md section 14.3); with the message heads
    shape: Callable[[env.Envelope], env.Envelope] | None = None
    unshape: Callable[[env.Envelope], env.Envelope] | None = None


def join_hooks(*hooks: PacketHooks | None) -> PacketHooks:
    """One `PacketHooks` from several (reliability's and the seal's, docs/seams.md section 5).

    `parts` are merged in order; C (`control`) items of several hooks are joined (the seal's
    sync request, the MAC's grants and ends). T (`time`) may come from both (each stamps its own wall clock
    as the packet is built, so they may differ by a tick): the first one given is kept. Any other
    part two hooks give must have the same value, otherwise building the packet fails with
    EnvelopeError.
    At most one hook may `seal` and `open` (the same one, or neither: ValueError otherwise); its
    `number` numbers the packets. `sent`, `received` and `carrying` are called in order;
    `overhead` is the sum (an upper bound: a part two hooks both give is counted twice),
    `next_overhead` the sum of each hook's (its `overhead` when it gives none). Likewise at most
    one hook may give the message heads (`stamp`, `head_room`, `admit`) and at most one
    `resend`; `ack_only` is any hook's, `next_time` the earliest, `stats` the union of the
    hooks' dicts, `part_room` the sum."""
    given = [h for h in hooks if h is not None]
    sealers = [h for h in given if h.seal is not None or h.open is not None or h.number is not None]
    if len(sealers) > 1:
        raise ValueError("at most one of the joined hooks may seal and open packets")
    sealer = sealers[0] if sealers else PacketHooks()
    makers = [h.parts for h in given if h.parts is not None]
    senders = [h.sent for h in given if h.sent is not None]
    receivers = [h.received for h in given if h.received is not None]

    def parts(now: float) -> dict:
        out: dict = {}
        for make in makers:
            for name, value in make(now).items():
                if name == "time" and name in out:
                    continue
                if name == "control" and name in out:
                    out[name] = out[name] + value     # C items of the seal and of the MAC
                    continue
                if name in out and out[name] != value:
                    raise env.EnvelopeError(f"two hooks give the envelope's {name} part "
                                            f"different values ({out[name]!r}, {value!r})")
                out[name] = value
        return out

    def sent(number: int, picked: list[tuple[int, bytes]], now: float) -> None:
        for tell in senders:
            tell(number, picked, now)

    def received(envelope: env.Envelope, now: float) -> None:
        for tell in receivers:
            tell(envelope, now)

    def next_overhead(now: float) -> int:
        return sum(h.next_overhead(now) if h.next_overhead is not None else h.overhead
                   for h in given)

    header = _one(given, ("stamp", "head_room", "admit", "shape", "unshape"), "give message heads")
    resender = _one(given, ("resend",), "re-send messages")
    carriers = [h.carrying for h in given if h.carrying is not None]
    askers = [h.ack_only for h in given if h.ack_only is not None]
    timers = [h.next_time for h in given if h.next_time is not None]
    reporters = [h.stats for h in given if h.stats is not None]
    roomers = [h.part_room for h in given if h.part_room is not None]

    def part_room(key: int) -> int:
        return sum(room(key) for room in roomers)

    def carrying(picked: list[tuple[int, bytes]], now: float) -> None:
        for tell in carriers:
            tell(picked, now)

    def ack_only(now: float) -> bool:
        return any(ask(now) for ask in askers)

    def next_time(now: float) -> float | None:
        times = [t for when in timers if (t := when(now)) is not None]
        return min(times) if times else None

    def stats() -> dict:
        out: dict = {}
        for report in reporters:
            out.update(report())
        return out

    return PacketHooks(parts=parts if makers else None, seal=sealer.seal, open=sealer.open,
                       sent=sent if senders else None, received=received if receivers else None,
                       overhead=sum(h.overhead for h in given),
                       next_overhead=(next_overhead if any(h.next_overhead is not None for h in given)
                                      else None),
                       number=sealer.number,
                       carrying=carrying if carriers else None, resend=resender.resend,
                       ack_only=ack_only if askers else None,
                       next_time=next_time if timers else None,
                       stamp=header.stamp, head_room=header.head_room, admit=header.admit,
                       shape=header.shape, unshape=header.unshape,
                       part_room=part_room if roomers else None,
                       stats=stats if reporters else None)


def _one(hooks: list[PacketHooks], names: tuple[str, ...], what: str) -> PacketHooks:
    """The one hook that gives any of `names` (an empty PacketHooks when none does)."""
    found = [h for h in hooks if any(getattr(h, n) is not None for n in names)]
    if len(found) > 1:
        raise ValueError(f"at most one of the joined hooks may {what}")
    return found[0] if found else PacketHooks()


def envelope_room(max_read_length: int, overhead: int = 0) -> int:
    """Bytes of messages one packet holds: the short frame's payload (wire format 3) minus P, W
    and `overhead`, plus one (the last message has no length byte, and `message_measure`
    counts one per message)."""
    return (min(max_read_length, MAX_PAYLOAD + SHORT_OVERHEAD) - SHORT_OVERHEAD - env.HEAD
            - overhead + 1)


def envelope_check(payload: bytes) -> bool:
    """Whether `payload` decodes as an envelope (a sealed one with any tag length a link may
    have): what the short frame's decoder asks of a start before it takes it. An envelope of
    wire format 3 is taken when it would decode with this build's version bits (3 is 4 without
    cut messages), so that the unpacker counts and logs its sender (`version_3`)."""
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

    def next_packet(self, now: float) -> bytes | None:
        picked: list[tuple[int, bytes]] = []
        messages: list[env.Message] = []
        h = self.hooks
        room = self.room
        charged = 0               # bytes of parts the picked messages bring (part_room)
        if h.next_overhead is not None:
            room = envelope_room(self.max_read_length, h.next_overhead(now))
        budget = room
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
            now, room if picked else None, fill=True, packet=self.number,
            extra=extra if roomy is not None else None))
        for source in sources:
            while budget > 1:
                got = source(budget)
                if got is None:
                    break
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
                budget = room - charged - len(env.encode_messages(messages)) - 1
        if not messages:
            if h.ack_only is None or not h.ack_only(now):
                return None
        if h.carrying is not None:
            h.carrying(picked, now)
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
        self.number = number + 1
        self.counters.inc("packets_sent")
        self.counters.inc("messages_sent", len(messages))
        if not messages:
            self.counters.inc("ack_only_sent")
        return data


class Unpacker:
    """Opens received envelopes; refuses (counted, logged once) what is not one."""

    def __init__(self, hooks: PacketHooks | None = None, *, counters: Counters, name: str = "link"):
        self.hooks = hooks or PacketHooks()
        self.counters = counters
        self.name = name

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
        if self.hooks.received is not None:
            self.hooks.received(envelope, now)
        out = []
        for m in envelope.messages:
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
