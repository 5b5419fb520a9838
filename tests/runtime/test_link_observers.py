"""The link's packet observers: every packet written and read, with what became of it."""
from __future__ import annotations

import random

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.wire.framing import encode_frame


def scenario() -> Scenario:
    return Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=64, per=0.0, seed=1, bitrate=4800.0)


def watch(link) -> list[tuple[str, bytes, str]]:
    seen: list[tuple[str, bytes, str]] = []
    link.observers.append(lambda now, direction, data, outcome: seen.append((direction, data, outcome)))
    return seen


def test_each_packet_written_is_seen_sent_and_read_delivered_with_the_same_bytes():
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    out, got = watch(sim.sender), watch(sim.receiver)
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=20))
    for n in range(8):
        sim.sender.offer(4, bytes((0, 4, n)) + bytes(10))
    sim.run(1.0)
    assert [o for _d, _b, o in out] == ["sent", "sent"] and {d for d, _b, _o in out} == {"tx"}
    # 11-byte bodies of one topic: runs of 5, then 3 (wire-format.md section 14)
    assert [(d, o) for d, _b, o in got] == [("rx", "delivered 5"), ("rx", "delivered 3")]
    assert [b for _d, b, _o in got] == [b for _d, b, _o in out]


def test_fragments_are_seen_as_such_until_the_message_completes():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, fragment_id=250, rng=random.Random(2))
    got = watch(sim.receiver)
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=5))
    sim.sender.offer(7, bytes((0, 7)) + random.Random(1).randbytes(200))
    sim.run(3.0)
    outcomes = [o for _d, _b, o in got]
    assert outcomes[-1] == "delivered 1" and set(outcomes[:-1]) == {"fragment"} and len(outcomes) >= 3


def test_packets_dropped_are_seen_with_their_reason():
    refuse = PacketHooks(admit=lambda payload, now: None)     # e.g. a copy, or stale
    sim = LinkSim(scenario(), "a", "b", wire_format=2, hooks=refuse)
    got = watch(sim.receiver)
    sim.sender.add_channel(4, LinkPolicy())
    sim.sender.offer(4, bytes((0, 4, 1)))
    sim.run(0.6)
    rx = sim.receiver.connection
    rx._deliver(rx.decoder.feed(encode_frame(bytes.fromhex("00 04 F5"))))   # a wire format 1 frame
    assert [o for _d, _b, o in got] == ["dropped not_admitted", "dropped bad_envelope"]


def test_a_failing_observer_never_stops_the_link(caplog):
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    sim.receiver.observers.append(lambda *a: 1 / 0)
    sim.sender.add_channel(4, LinkPolicy())
    sim.sender.offer(4, bytes((0, 4, 1)))
    sim.run(0.6)
    assert [p for _t, p in sim.received] == [bytes((0, 4, 1))]
    assert "a packet observer failed" in caplog.text


def test_wire_format_1_payloads_are_observed_too():
    sim = LinkSim(scenario(), "a", "b")
    out, got = watch(sim.sender), watch(sim.receiver)
    sim.sender.add_channel(4, LinkPolicy())
    sim.sender.offer(4, bytes((0, 4, 1)))
    sim.run(0.6)
    assert out == [("tx", bytes((0, 4, 1)), "sent")] and got == [("rx", bytes((0, 4, 1)), "delivered 1")]
