"""Reliability wired into wire format 2 links (uwgen.runtime.delivery.reliability): acks ride on packets,
lost reliable messages are sent again and delivered once, the ledger closes from packet numbers,
stale commands are refused, bad input is counted."""
from __future__ import annotations

import logging

from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire import envelope
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.framing import ShortFrameDecoder
from uwgen.runtime.delivery.reliability import Reliability

RELIABLE = LinkPolicy(queue="fifo", depth=100, ttl=30.0, reliable=True)
BEST_EFFORT = LinkPolicy(queue="fifo", depth=100, ttl=30.0)
WALL0 = 1.7e9


class Wall:
    """A wall clock that follows the simulation's clock, `offset` seconds apart."""

    def __init__(self, clock: ManualClock, offset: float = 0.0):
        self.clock, self.offset = clock, offset

    def now(self) -> float:
        return WALL0 + self.clock.now() + self.offset


def duplex(per: float = 0.0, seed: int = 1, *, max_ages=None, offsets=None,
           clock_exchange: bool = False) -> tuple[DuplexSim, dict]:
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.5, max_read_length=64, per=per, seed=seed, bitrate=4800.0)
    clock = ManualClock()
    engines = {}

    def hooks_for(side: str):
        engines[side] = Reliability(1 if side == "a" else 2, period=0.5, reliable={7: 30.0},
                                    max_ages=max_ages if max_ages is not None else {7: 30.0},
                                    wall=Wall(clock, (offsets or {}).get(side, 0.0)), name=side,
                                    max_read_length=64, clock_exchange=clock_exchange)
        return engines[side].hooks()
    sim = DuplexSim(scen, ("a", "b"), hooks_for=hooks_for, wire_format=2, clock=clock)
    return sim, engines


def numbers(sim: DuplexSim, side: str, ident: int) -> list[int]:
    return [p[2] for _, p in sim.received[side] if p[1] == ident]


def two_way(sim: DuplexSim, a_sends: int, b_sends: int, b_after: float = 0.3):
    """Traffic both ways, one message a second each: a offers reliable topic 7, b best-effort
    topic 4 (`b_after` s after a); message i carries i. Returns the links (a, b)."""
    a, b = sim.links["a"], sim.links["b"]
    a.add_channel(7, RELIABLE)
    b.add_channel(4, BEST_EFFORT)
    for i in range(a_sends):
        sim.at(i * 1.0, lambda i=i: a.offer(7, bytes((0, 7, i)) + bytes(10)))
    for i in range(b_sends):
        sim.at(i * 1.0 + b_after, lambda i=i: b.offer(4, bytes((0, 4, i)) + bytes(5)))
    return a, b


def closes(row: dict) -> bool:
    return row["sent"] == (row["delivered"] + row["lost_on_link"] + row["in_flight"]
                           + row["unacknowledged"] + row.get("unknown", 0))


def test_a_reliable_topic_arrives_complete_and_once_at_30_percent_loss():
    sim, rel = duplex(per=0.3)
    a, b = two_way(sim, 40, 40)
    sim.run(120.0)
    assert sorted(numbers(sim, "b", 7)) == list(range(40))          # all, each once
    row = a.stats()["ledger"][7]
    # a lost copy is sent again unless another one (sent in spare room) was on its way
    copies = a.stats()["reliability"]["copies"]
    assert row["lost_on_link"] > 0 and row["resent"] + copies >= row["lost_on_link"] - row["expired"]
    assert closes(row) and row["in_flight"] == 0
    assert b.stats()["ledger"][7]["duplicates"] == rel["b"].engine.duplicates.get(7, 0)


def test_lost_on_link_is_exactly_what_the_peer_sent_and_never_arrived():
    sim, _ = duplex(per=0.25, seed=3)
    a, b = two_way(sim, 80, 40)          # a goes on sending after b stopped: its acks ride
    sim.run(90.0)
    row = b.stats()["ledger"][4]
    arrived = len(numbers(sim, "a", 4))
    assert row["sent"] == 40 and arrived < 40
    assert (row["delivered"], row["lost_on_link"], row["in_flight"]) == (arrived, 40 - arrived, 0)


def test_a_message_lost_once_is_sent_again_and_delivered_once():
    sim, _ = duplex()
    a = sim.links["a"]
    a.add_channel(7, RELIABLE)
    sim.drop("a", 0)                       # the first packet, which carries message 0
    sim.at(0.0, lambda: a.offer(7, bytes((0, 7, 0)) + bytes(10)))
    sim.run(30.0)
    assert numbers(sim, "b", 7) == [0]
    row = a.stats()["ledger"][7]
    assert (row["lost_on_link"], row["resent"], row["delivered"]) == (1, 1, 1)
    assert a.stats()["packets"]["packets_sent"] >= 2


def test_a_copy_sent_because_the_ack_was_lost_is_delivered_once_and_counted():
    sim, _ = duplex()
    a, b = sim.links["a"], sim.links["b"]
    a.add_channel(7, RELIABLE)
    sim.drop("b", 0)                        # b's ack (alone: b has nothing else) is lost
    sim.at(0.0, lambda: a.offer(7, bytes((0, 7, 5)) + bytes(10)))
    sim.run(40.0)
    assert numbers(sim, "b", 7) == [5]
    assert b.stats()["ledger"][7]["duplicates"] == 1
    row = a.stats()["ledger"][7]
    # both copies arrived (the first one's ack was lost): both are counted delivered
    assert (row["sent"], row["resent"], row["delivered"], row["in_flight"]) == (2, 1, 2, 0)
    assert a.stats()["reliability"]["spurious_resends"] == 1


def test_acks_ride_on_packets_going_the_other_way_and_go_alone_only_when_due():
    sim, _ = duplex()
    a, b = two_way(sim, 20, 20, b_after=0.2)
    sim.run(25.0)
    assert a.stats()["ledger"][7]["delivered"] == 20
    # b answers with its own traffic: acks ride on it, at most one goes alone at the end
    assert b.stats()["packets"]["ack_only_sent"] <= 2
    assert b.stats()["packets"]["packets_sent"] <= 22


def test_a_command_older_than_its_max_age_is_refused_and_counted_stale(caplog):
    # before any exchange the clocks are taken within 5 s of each other: a max age of 8 s
    # takes a fresh command (at most 0.25 + 0.8 + 5 s old), not one that waited 10 s
    sim, rel = duplex(max_ages={7: 30.0, 9: 8.0})
    a = sim.links["a"]
    a.add_channel(9, LinkPolicy(queue="fifo", depth=4))       # no ttl on the sending side
    sim.clock.set(20.0)
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        a.offer(9, bytes((2, 9, 1, 0xF5)), published=10.0)    # waited 10 s before leaving
        a.offer(9, bytes((2, 9, 2, 0xF5)))                    # fresh
        sim.run(30.0)
    assert numbers(sim, "b", 9) == [2]
    assert rel["b"].counters["stale"] == 1 and rel["b"].stale_by_id == {9: 1}
    assert "max age is 8.0 s" in caplog.text


def test_a_transit_that_cannot_be_told_from_an_offset_is_refused_never_judged_by_age_alone(caplog):
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0}, offsets={"b": 60.0})
    a = sim.links["a"]
    a.add_channel(9, LinkPolicy(queue="fifo", depth=4))
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        for i in range(3):
            sim.at(i * 2.0, lambda i=i: a.offer(9, bytes((2, 9, i, 0xF5))))
        sim.run(10.0)
    assert numbers(sim, "b", 9) == []
    assert rel["b"].counters["unexplained_delay"] == 3 and rel["b"].counters["stale"] == 0
    assert "from sender 1: its packet's time says it took 60." in caplog.text


def test_a_message_with_a_max_age_on_a_packet_without_time_is_refused_untimed(caplog):
    # an age item alone bounds no hold: a packet held an hour carries the same age 0
    sim, rel = duplex(max_ages={7: 30.0, 9: 8.0})
    b = sim.links["b"]
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        b._on_packet(envelope.Envelope(1, 0, (envelope.Message(2, 9, b"\x00\x01\xf5"),)).encode())
    assert sim.received["b"] == []
    assert rel["b"].counters["untimed"] == 1 and rel["b"].stale_by_id == {9: 1}
    assert "has no time (T)" in caplog.text


def test_time_goes_only_on_packets_carrying_a_message_with_a_max_age():
    sim, _ = duplex(max_ages={9: 5.0})
    a = sim.links["a"]
    a.add_channel(9, LinkPolicy(queue="fifo", depth=4))
    a.add_channel(4, BEST_EFFORT)
    sim.at(0.0, lambda: a.offer(4, bytes((0, 4, 1))))
    sim.at(2.0, lambda: a.offer(9, bytes((2, 9, 1, 0xF5))))
    sent = []
    conn = a.connection
    take = conn.outbox.take

    def spy(now, pull, fit=None):
        batch = take(now, pull, fit)
        sent.extend(envelope.decode(f) for f in ShortFrameDecoder().feed(batch))
        return batch
    conn.outbox.take = spy
    sim.run(5.0)
    by_id = {e.messages[0].id: e for e in sent if e.messages}
    assert by_id[4].time is None
    assert by_id[9].time == int((WALL0 + 2.0) * 32) % (1 << 24)


def test_malformed_acks_and_heads_are_counted_and_logged_never_crash(caplog):
    sim, rel = duplex(max_ages={7: 30.0, 9: 2.0})
    b = sim.links["b"]
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        for number in range(3):
            b._on_packet(envelope.Envelope(1, number, (envelope.Message(0, 7, b""),),
                                           ack=b"\x20\x00").encode())
        b._on_packet(envelope.Envelope(1, 3, (envelope.Message(2, 9, b"\x19"),)).encode())
    assert rel["b"].counters["bad_acks"] == 3 and rel["b"].counters["bad_heads"] == 4
    assert sim.received["b"] == []
    assert caplog.text.count("malformed") == 2          # throttled: first of each only


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40), st.binary(max_size=12), st.integers(0, 4095), st.integers(0, 15))
def test_any_a_part_and_any_body_are_taken_or_counted_never_raise(ack, body, number, sender):
    rel = Reliability(2, period=0.5, reliable={7: 30.0}, max_ages={7: 30.0, 9: 2.0},
                      wall=Wall(ManualClock()), name="fuzz")
    hooks = rel.hooks()
    for ident in (7, 9, 11):
        hooks.received(envelope.Envelope(sender, number, (envelope.Message(0, ident, body),),
                                         ack=ack or None), 1.0)
        out = hooks.admit(bytes((0, ident)) + body, 1.0)
        assert out is None or out.startswith(bytes((0, ident)))
    counted = rel.counters["bad_heads"] + rel.counters["stale"] + sum(rel.engine.duplicates.values())
    assert counted <= 3
