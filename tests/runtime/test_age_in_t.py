"""One age item a packet left out (docs/wire-format.md section 14.3): a packet with T, no K, no A
and no fragment carrying exactly one message with a max age sends that message's publication
time as T and no age item; the receiver puts the item back, so it judges the same age, a held
packet included."""
from __future__ import annotations

import pytest

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.freshness import TICKS_PER_SECOND, stamp
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.envelope import Envelope, Message, Sync
from uwgen.runtime.wire.heads import AGE_UNIT, Heads, decode_age, encode_age

HEADS = Heads(numbered=frozenset({7}), aged=frozenset({7, 9}))
T = 0x7E2010


def published(e: Envelope, heads: Heads = HEADS) -> list[float]:
    """Each aged message's publication time as the receiver reads it: T minus its age, in ticks."""
    out = []
    for m in e.messages:
        if m.id in heads.aged:
            age, _ = decode_age(m.body, 1 if m.id in heads.numbered else 0)
            out.append(e.time - age * TICKS_PER_SECOND)
    return out


@pytest.mark.parametrize("ident, body, sent", [
    (9, encode_age(1.25) + b"\xf5", b"\xf5"),                  # an aged command: age 5 units
    (7, b"\x2a" + encode_age(100.0) + b"\xf5", b"\x2a\xf5"),   # reliable and aged: N stays
])
def test_a_lone_aged_message_leaves_its_age_in_t_and_gets_it_back(ident, body, sent):
    e = Envelope(1, 0x10, (Message(2, ident, body),), time=T)
    out = HEADS.without_age(e, TICKS_PER_SECOND)
    age, _ = decode_age(body, 1 if ident == 7 else 0)
    assert out.messages[0].body == sent
    assert out.time == T - int(age / AGE_UNIT) * TICKS_PER_SECOND // 4
    assert len(out.encode()) == len(e.encode()) - len(encode_age(age))
    back = HEADS.with_age(envelope.decode(out.encode()))
    assert published(back) == published(e)         # the same publication time, read the same way


@pytest.mark.parametrize("change", ["no T", "K", "A", "fragment", "two aged", "none aged",
                                    "another message"])
def test_t_stays_the_build_time_otherwise(change):
    msgs = [Message(2, 9, encode_age(0.5) + b"\xf5")]
    kw = dict(time=T)
    if change == "no T":
        kw = {}
    elif change == "K":
        kw["sync"] = Sync(bytes(6), 0)
    elif change == "A":
        kw["ack"] = b"\x11\x51\x05"
    elif change == "fragment":
        msgs.append(Message(envelope.FRAGMENT, 0, b"\x07\x00\x03\x00"))
    elif change == "two aged":
        msgs.append(Message(0, 7, b"\x01" + encode_age(0.0)))
    elif change == "another message":
        msgs.append(Message(0, 4, b"\x01"))
    else:
        msgs = [Message(0, 4, b"\x01")]
    e = Envelope(1, 3, tuple(msgs), **kw)
    assert HEADS.without_age(e, TICKS_PER_SECOND) == e
    assert HEADS.with_age(e) == e


def test_sides_that_know_different_aged_ids_agree_on_which_packet_is_lone():
    # a fleet: the surface knows both vehicles' commands (10, 20) as aged, vehicle 1 only its
    # own; a packet of both keeps every age item, read the same way by each
    surface, vehicle1 = Heads(aged=frozenset({10, 20})), Heads(aged=frozenset({10}))
    e = Envelope(1, 3, (Message(0, 10, encode_age(3.0) + b"\x01"),
                        Message(0, 20, encode_age(1.0) + b"\x02")), time=T)
    sent = surface.without_age(e, TICKS_PER_SECOND)
    assert sent == e and vehicle1.with_age(envelope.decode(sent.encode())) == e
    alone = Envelope(1, 4, (Message(0, 20, encode_age(1.0) + b"\x02"),), time=T)
    sent = surface.without_age(alone, TICKS_PER_SECOND)
    assert sent != alone and vehicle1.with_age(envelope.decode(sent.encode())) == sent  # not its entry


def duplex(offsets: dict[str, float] | None = None) -> tuple[DuplexSim, dict[str, Reliability]]:
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.5, max_read_length=64, per=0.0, seed=1, bitrate=4800.0)
    clock = ManualClock()
    engines = {}

    class Wall:
        def __init__(self, side):
            self.off = (offsets or {}).get(side, 0.0)

        def now(self):
            return 1.7e9 + clock.now() + self.off

    def hooks_for(side):
        engines[side] = Reliability(1 if side == "a" else 2, period=0.5, reliable={},
                                    max_ages={9: 30.0}, wall=Wall(side), name=side, max_read_length=64)
        return engines[side].hooks()
    return DuplexSim(scen, ("a", "b"), hooks_for=hooks_for, wire_format=2, clock=clock), engines


def test_commands_arrive_and_a_held_one_is_still_refused_however_long_the_hold():
    sim, rel = duplex()
    a = sim.links["a"]
    a.add_channel(9, LinkPolicy(queue="fifo", depth=8))
    sent = []
    take = a.connection.outbox.take

    def spy(now, pull, fit=None):
        batch = take(now, pull, fit)
        sent.append(batch)
        return batch
    a.connection.outbox.take = spy
    sim.hold("a", 3600.0, 1)                 # the second packet: held an hour
    for i in range(3):
        sim.at(2.0 * i, lambda i=i: a.offer(9, bytes((2, 9, i, 0xF5)), published=2.0 * i - 1.0))
    sim.run(3700.0)
    got = [p[2] for _, p in sim.received["b"] if p[1] == 9]
    assert got == [0, 2]                     # taken fresh; the held one refused
    assert rel["b"].counters["stale"] + rel["b"].counters["unexplained_delay"] == 1
    lone = [e for batch in sent if batch for e in map(envelope.decode, frames(batch))
            if e.messages and e.ack is None and e.sync is None]
    assert lone and all(len(e.messages[0].body) == 2 for e in lone)   # seq and F5: no age item on the air
    assert all(e.time is not None for e in lone)


def frames(batch: bytes) -> list[bytes]:
    from uwgen.runtime.wire.framing import ShortFrameDecoder
    return ShortFrameDecoder().feed(batch)


def test_the_publication_time_in_t_is_the_build_time_less_the_age():
    heads = Heads(aged=frozenset({9}))
    built = 1_700_000_000.5
    e = Envelope(1, 0x10, (Message(2, 9, encode_age(0.5) + b"\x07\xf5"),), time=stamp(built))
    out = heads.without_age(e, TICKS_PER_SECOND)
    assert out.time == stamp(built - 0.5) == 0x7E2000
    assert out.encode().hex(" ").upper() == "84 10 10 7E 20 00 29 07 F5"


def test_a_message_whose_max_age_is_over_the_seals_default_keeps_its_age_item():
    # a sealed packet's T is checked against the seal's default max age (120 s): a message that
    # may have waited longer than that keeps T the build time
    rel = Reliability(1, period=0.5, reliable={}, max_ages={9: 30.0, 11: 600.0}, name="a")
    assert rel.heads.lone == frozenset({9})
    for ident, shaped in ((9, True), (11, False)):
        e = Envelope(1, 3, (Message(2, ident, encode_age(0.5) + b"\xf5"),), time=T)
        assert (rel.shape(e) != e) == shaped
        assert rel.heads.with_age(rel.shape(e)) == (Envelope(1, 3, (Message(2, ident, encode_age(0.0) + b"\xf5"),),
                                                             time=T - 16) if shaped else e)
