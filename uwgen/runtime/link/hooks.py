"""The hooks a packet's parts come from (docs/seams.md sections 5 and 9): what reliability
(wire-format.md section 15), the per-packet seal (section 12.2) and the MAC (section 16) plug
into the packer and the unpacker (uwgen/runtime/link/packets.py), and `join_hooks`, which makes
one set of hooks from several. A `received` hook that answers False (reliability's, for a packet
number already received: DESERT delivered the packet twice) stops the packet: the hooks after
it (the MAC's grants) and the messages never see it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from uwgen.runtime.wire import envelope as env


@dataclass
class PacketHooks:
    """What reliability (wire-format.md section 15) and the per-packet seal (section 12.2) plug
    into; all optional."""

    parts: Callable[[float], dict] | None = None
    seal: Callable[[env.Envelope], bytes] | None = None
    open: Callable[[bytes], env.Envelope | None] | None = None
    sent: Callable[[int, list[tuple[int, bytes]], float], None] | None = None
    # told every envelope accepted; False: a repeat of a packet received, dropped whole
    received: Callable[[env.Envelope, float], bool | None] | None = None
    overhead: int = 0
    next_overhead: Callable[[float], int] | None = None
    number: Callable[[], int] | None = None
    # (picked, now, fresh): the packet's messages, and whether any is not a copy
    carrying: Callable[[list[tuple[int, bytes]], float, bool], None] | None = None
    # packet `number`'s last message was cut, its tail starts the next packet (or, moved=True,
    # the message goes whole in the next packet): wire-format.md section 14.2
    cut: Callable[..., None] | None = None
    resend: Callable[[float, int], tuple[int, bytes] | None] | None = None
    copy: Callable[[float, int, bool], tuple[int, bytes] | None] | None = None   # (now, room, fresh)
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
    `number` numbers the packets. `sent`, `received`, `carrying` and `cut` are called in order
    (`received` until one answers False: the packet is a repeat, and so is the joined answer);
    `overhead` is the sum (an upper bound: a part two hooks both give is counted twice),
    `next_overhead` the sum of each hook's (its `overhead` when it gives none). Likewise at most
    one hook may give the message heads (`stamp`, `head_room`, `admit`) and at most one
    `resend` and `copy`; `ack_only` is any hook's, `next_time` the earliest, `stats` the union of the
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

    def received(envelope: env.Envelope, now: float) -> bool:
        for tell in receivers:
            if tell(envelope, now) is False:
                return False        # a repeat: the hooks after this one never see it
        return True

    def next_overhead(now: float) -> int:
        return sum(h.next_overhead(now) if h.next_overhead is not None else h.overhead
                   for h in given)

    header = _one(given, ("stamp", "head_room", "admit", "shape", "unshape"), "give message heads")
    resender = _one(given, ("resend", "copy"), "re-send messages")
    carriers = [h.carrying for h in given if h.carrying is not None]
    cutters = [h.cut for h in given if h.cut is not None]
    askers = [h.ack_only for h in given if h.ack_only is not None]
    timers = [h.next_time for h in given if h.next_time is not None]
    reporters = [h.stats for h in given if h.stats is not None]
    roomers = [h.part_room for h in given if h.part_room is not None]

    def part_room(key: int) -> int:
        return sum(room(key) for room in roomers)

    def carrying(picked: list[tuple[int, bytes]], now: float, fresh: bool = True) -> None:
        for tell in carriers:
            tell(picked, now, fresh)

    def cut(number: int, moved: bool = False) -> None:
        for tell in cutters:
            tell(number, moved)

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
                       carrying=carrying if carriers else None, resend=resender.resend, copy=resender.copy,
                       cut=cut if cutters else None,
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
