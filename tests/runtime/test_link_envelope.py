"""Links in wire format 2: one envelope per write, several messages per packet, the same payloads out."""
from __future__ import annotations

import logging
import random

from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import ShortFrameDecoder, encode_frame, encode_short_frame
from uwgen.runtime.link.hooks import PacketHooks


def scenario(per: float = 0.0, seed: int = 1, mrl: int = 64) -> Scenario:
    return Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=mrl, per=per, seed=seed, bitrate=4800.0)


def envelopes(sim: LinkSim) -> list[envelope.Envelope]:
    return [envelope.decode(f) for d in sim.packets for f in ShortFrameDecoder().feed(d.data)]


def test_one_packet_carries_several_messages_in_one_envelope():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, sender_id=3)
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=20))
    sent = [bytes((0, 4, n)) + bytes(10) for n in range(8)]
    for p in sent:
        sim.sender.offer(4, p)
    sim.run(1.0)
    assert [p for _, p in sim.received] == sent
    # bodies of 11 bytes of one id: a run (H 62, H' 04, n) of 5 fits (frame 1, P W 3, 3 + 5 x 11)
    assert len(sim.packets) == 2 and [len(d.data) for d in sim.packets] == [62, 40]
    envs = envelopes(sim)
    assert [e.number for e in envs] == [0, 1] and {e.sender for e in envs} == {3}
    assert [len(e.messages) for e in envs] == [5, 3]


def test_packed_ids_travel_without_their_byte_string_head():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, packed_ids={5})
    sim.sender.add_channel(5, LinkPolicy())
    sim.sender.offer(5, bytes.fromhex("00 05 42 7D 23"))
    sim.run(0.5)
    assert [p for _, p in sim.received] == [bytes.fromhex("00 05 42 7D 23")]
    # the short frame: LEN, then P, W, H = 05 and the two bytes of fields: 3 bytes of message
    assert sim.packets[0].data == bytes.fromhex("06 80 00 00 05 7D 23")


def test_a_payload_of_a_packed_id_that_is_not_packed_is_refused_and_counted(caplog):
    sim = LinkSim(scenario(), "a", "b", wire_format=2, packed_ids={5})
    sim.sender.add_channel(5, LinkPolicy())
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        assert not sim.sender.offer(5, bytes.fromhex("00 05 F5"))
    assert sim.sender.counters["not_packed"] == 1 and "not packed" in caplog.text


def test_large_messages_go_as_fragments_inside_envelopes_that_fit_a_packet():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, fragment_id=250, rng=random.Random(2))
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=5))
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=5, priority=3))
    big = bytes((0, 7)) + random.Random(1).randbytes(400)
    sim.sender.offer(7, big)
    sim.sender.offer(4, bytes.fromhex("00 04 01 02"))
    sim.run(3.0)
    assert sorted(p for _, p in sim.received) == sorted([big, bytes.fromhex("00 04 01 02")])
    assert all(len(d.data) <= 64 for d in sim.packets)
    assert sim.receiver.stats()["fragments"]["completed"] == 1
    # the fragments are compact fragment messages (H 61), each filling its packet: 402 bytes in
    # chunks of 56 (room 61: H, transfer, index, count, a length byte unless last), 8 of them
    frags = [m for e in envelopes(sim) for m in e.messages if m.kind == envelope.FRAGMENT]
    assert [m.body[1:3] for m in frags] == [bytes((i, 8)) for i in range(8)]
    assert [len(m.body) - 3 for m in frags] == [56] * 7 + [402 - 7 * 56]


def test_a_v1_peer_is_refused_counted_and_logged_once(caplog):
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    got = []
    sim.receiver._on_payload = got.append
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        for _ in range(3):
            sim.receiver.connection._deliver(sim.receiver.connection.decoder.feed(
                encode_frame(bytes.fromhex("00 04 F5"))))
    assert got == []
    assert sim.receiver.stats()["packets"]["version_1"] == 3
    assert caplog.text.count("wire format 1") == 1


def test_a_wire_format_2_peer_is_counted_and_logged_once(caplog):
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    got = []
    sim.receiver._on_payload = got.append
    conn = sim.receiver.connection
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        for _ in range(3):
            conn._deliver(conn.decoder.feed(encode_frame(bytes.fromhex("40 10 05 04 7D 23"))))
    assert got == [] and sim.receiver.stats()["packets"]["version_2"] == 3
    assert caplog.text.count("wire format 2") == 1


def test_an_envelope_link_reports_the_wire_format_it_speaks():
    from uwgen.runtime.wire.envelope import VERSION
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    assert sim.sender.stats()["wire_format"] == VERSION == 4
    assert LinkSim(scenario(), "a", "b").sender.stats()["wire_format"] == 1


def test_a_wire_format_3_peer_is_counted_and_logged_once(caplog):
    # its short frames reach the envelope layer (the frame decoder takes their starts)
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    got = []
    sim.receiver._on_payload = got.append
    conn = sim.receiver.connection
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        conn._deliver(conn.decoder.feed(bytes.fromhex("06 60 10 05 04 7D 23") * 3))
    assert got == [] and sim.receiver.stats()["packets"]["version_3"] == 3
    assert caplog.text.count("wire format 3") == 1


def test_garbage_envelopes_are_counted_not_delivered():
    sim = LinkSim(scenario(), "a", "b", wire_format=2)
    got = []
    sim.receiver._on_payload = got.append
    conn = sim.receiver.connection
    conn._deliver(conn.decoder.feed(encode_frame(bytes.fromhex("80 00 00 84 09 01"))
                                    + encode_frame(bytes.fromhex("80 00 00 60 07 04 01"))
                                    + encode_short_frame(bytes.fromhex("80 00 01 07 F5"))))
    assert got == [bytes.fromhex("00 07 F5")]
    stats = sim.receiver.stats()["packets"]
    assert stats["bad_envelopes"] == 1 and stats["unknown_kind"] == 1


def test_hooks_see_each_packet_with_its_messages_and_can_add_parts():
    sent, received = [], []
    hooks = PacketHooks(parts=lambda now: {"time": 7}, overhead=4,
                        sent=lambda number, msgs, now: sent.append((number, [k for k, _ in msgs])),
                        received=lambda env, now: received.append((env.number, env.time)))
    sim = LinkSim(scenario(), "a", "b", wire_format=2, hooks=hooks)
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=20))
    sim.sender.add_channel(6, LinkPolicy(queue="fifo", depth=20))
    for n in range(4):
        sim.sender.offer(4, bytes((0, 4, n)) + bytes(20))
        sim.sender.offer(6, bytes((0, 6, n)) + bytes(20))
    sim.run(1.5)
    assert len(sim.received) == 8
    assert [n for n, _ in sent] == list(range(len(sent))) and sum(len(k) for _, k in sent) == 8
    assert received == [(n, 7) for n, _ in sent]


@settings(max_examples=15, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 3), st.integers(1, 70)), min_size=1, max_size=40),
       st.integers(0, 10_000))
def test_with_loss_exactly_the_messages_of_arrived_packets_arrive_in_channel_order(offers, seed):
    sim = LinkSim(scenario(per=0.2, seed=seed), "a", "b", wire_format=2, fragment_id=250,
                  rng=random.Random(seed))
    for key in (1, 2, 3):
        sim.sender.add_channel(key, LinkPolicy(queue="fifo", depth=100, priority=key % 2))
    for n, (key, size) in enumerate(offers):
        sim.sender.offer(key, bytes([0, key]) + n.to_bytes(2, "big") + bytes(size))
    sim.run(len(offers) * 0.4 + 3.0)
    assert all(len(d.data) <= 64 for d in sim.packets)
    payloads = [p for _, p in sim.received]
    sent = {bytes([0, k]) + n.to_bytes(2, "big") + bytes(s) for n, (k, s) in enumerate(offers)}
    assert set(payloads) <= sent and len(payloads) == len(set(payloads))
    # a message that fits one packet arrives exactly when its packet arrived (a cut one
    # needs both of its packets: test_cut_link.py)
    small_in_packets = {envelope.to_v1(m) for e in envelopes(sim) for m in e.messages
                        if m.kind != envelope.FRAGMENT and not m.cut}
    assert small_in_packets <= set(payloads)
    for key in (1, 2, 3):
        serials = [int.from_bytes(p[2:4], "big") for p in payloads if p[1] == key]
        assert serials == sorted(serials)
