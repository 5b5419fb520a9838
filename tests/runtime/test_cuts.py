"""Cut messages (docs/wire-format.md section 14.2): the two message forms, joining them, and the
packer that cuts a message to fill a packet's tail."""
from __future__ import annotations

import random
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator.linksim import LinkSim
from uwgen.emulator.scenario import NodeSpec, Scenario
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.link.filling import CUT_MIN, cut_point
from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.cuts import Joiner, cut
from uwgen.runtime.wire.framing import ShortFrameDecoder

TWIST = env.Message(0, 5, bytes(range(30)))


def scenario(per: float = 0.0, seed: int = 1, mrl: int = 64) -> Scenario:
    return Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=mrl, per=per, seed=seed, bitrate=4800.0)


def envelopes(sim: LinkSim) -> list[env.Envelope]:
    d = ShortFrameDecoder()
    return [env.decode(f) for p in sim.packets for f in d.feed(p.data)]


# -- the forms ----------------------------------------------------------------------------

def test_a_cut_head_ends_the_packet_and_its_tail_starts_the_next():
    head, tail = cut(TWIST, 10)
    first = env.Envelope(1, 7, (env.Message(0, 4, b"ab"), head))
    second = env.Envelope(1, 8, (tail, env.Message(0, 4, b"cd")))
    assert first.encode() == bytes.fromhex("80 10 07 84 02 61 62 63 05") + bytes(range(10))
    assert second.encode() == (bytes.fromhex("80 10 08 E4 14") + bytes(range(10, 30))
                               + bytes.fromhex("04 63 64"))
    assert env.decode(first.encode()) == first and env.decode(second.encode()) == second


def test_the_encoder_puts_the_tail_first_and_the_head_last_whatever_the_order_given():
    head, tail = cut(TWIST, 10)
    e = env.Envelope(1, 7, (head, env.Message(0, 4, b"ab"), tail))
    assert env.decode(e.encode()).messages == (tail, env.Message(0, 4, b"ab"), head)


@pytest.mark.parametrize("data, why", [
    ("80 10 07 84 01 61 E4 01 02 03", "always the first"),           # a tail after a message
    ("80 10 07 E3 05 01 02 04 61", "last message"),                  # a head with a length
    ("80 10 07 63 61 01 02", "not a message's"),                     # a head's H is a fragment
    ("80 10 07 63 05", "no bytes"),                                  # an empty head
    ("80 10 07 E4 00 04 61", "no bytes"),                            # an empty tail
    ("80 10 07 E4 02 01 02", "followed by another"),                 # a tail with a length, last
])
def test_misplaced_or_empty_cut_parts_are_refused(data, why):
    with pytest.raises(env.EnvelopeError, match=why):
        env.decode(bytes.fromhex(data))


def test_a_cut_part_is_no_payload_until_it_is_joined():
    with pytest.raises(env.EnvelopeError):
        env.to_v1(cut(TWIST, 10)[0])
    with pytest.raises(env.EnvelopeError):
        cut(TWIST, 30)                                       # the tail would be empty


@given(st.binary(min_size=2, max_size=60), st.data())
@settings(max_examples=200)
def test_any_cut_round_trips_and_joins_to_the_message(body, data):
    m = env.Message(data.draw(st.sampled_from((0, 2, 3))), data.draw(st.integers(1, 255)), body)
    at = data.draw(st.integers(1, len(body) - 1))
    head, tail = cut(m, at)
    j = Joiner()
    a = env.decode(env.Envelope(2, 4095, (head,)).encode())
    b = env.decode(env.Envelope(2, 0, (tail,)).encode())           # 4095 + 1 wraps to 0
    assert j.feed(a) == [] and j.feed(b) == [m] and j.joined == 1 and j.orphans == 0


# -- joining ------------------------------------------------------------------------------

def test_a_tail_whose_head_was_lost_is_an_orphan_and_so_is_a_head_whose_tail_was():
    head, tail = cut(TWIST, 10)
    j = Joiner()
    assert j.feed(env.Envelope(1, 7, (head,))) == []
    # packet 8 was lost: packet 9's tail belongs to another message
    assert j.feed(env.Envelope(1, 9, (tail, env.Message(0, 4, b"x")))) == [env.Message(0, 4, b"x")]
    assert j.orphans == 1 and j.joined == 0
    j.feed(env.Envelope(1, 10, (env.Message(0, 4, b"y"), head)))
    assert j.feed(env.Envelope(1, 11, (env.Message(0, 4, b"z"),))) == [env.Message(0, 4, b"z")]
    assert j.orphans == 2 and j.pending == 0


def test_parts_join_only_within_one_sender_and_one_epoch():
    head, tail = cut(TWIST, 10)
    j = Joiner()
    j.feed(env.Envelope(1, 7, (head,), sync=env.Sync(b"AAAAAA", 0)))
    assert j.feed(env.Envelope(2, 8, (tail,))) == []           # another sender's packet 8
    assert j.feed(env.Envelope(1, 8, (tail,), sync=env.Sync(b"BBBBBB", 0))) == []  # restarted
    assert j.orphans == 2
    j.feed(env.Envelope(1, 9, (head,)))
    assert j.feed(env.Envelope(1, 10, (tail,))) == [TWIST]       # same epoch (K seen before)


# -- where to cut -------------------------------------------------------------------------

def test_the_cut_fills_the_packet_to_its_last_byte_and_leaves_a_tail_that_fits():
    before = [env.Message(0, 5, bytes(30))]
    limit = 64 - 1 - 3                       # a 64-byte packet's messages: 60 bytes
    at = cut_point(before, TWIST, limit, room=61)
    # 32 bytes (H, length, 30) and the head's 63 05: 26 bytes of body fill the 60
    assert at == 26
    assert len(env.encode_messages([*before, cut(TWIST, at)[0]])) == limit
    assert cut_point(before, TWIST, 32 + 2 + CUT_MIN - 1, room=61) is None   # too little left
    assert cut_point(before, TWIST, limit, room=2 + 30 - 27) is None         # tail won't fit


# -- on a link ----------------------------------------------------------------------------

def saturated(policy: LinkPolicy, per: float = 0.0, seed: int = 1, n: int = 60) -> LinkSim:
    sim = LinkSim(scenario(per, seed), "a", "b", wire_format=2, sender_id=1, fragment_id=250,
                  rng=random.Random(seed))
    sim.sender.add_channel(5, policy)
    sim.receiver.add_channel(5, policy)
    for i in range(n):
        sim.sender.offer(5, bytes((0, 5)) + i.to_bytes(2, "big") + bytes(28))
    sim.run(n * 0.2 + 2.0)
    return sim


def test_a_saturated_link_cuts_to_fill_every_packet_and_delivers_every_message_in_order():
    sim = saturated(LinkPolicy(queue="fifo", depth=100))
    got = [int.from_bytes(p[2:4], "big") for _, p in sim.received]
    assert got == list(range(60))
    es = envelopes(sim)
    full = [len(p.data) for p in sim.packets[:-1]]
    # every packet but the last is full, but for less room than a head (63 05), the length
    # byte it gives the message before it and CUT_MIN bytes of body
    assert min(full) > 64 - 2 - 1 - CUT_MIN and sum(full) / len(full) > 63
    assert sum(e.messages[-1].kind & env.CUT_HEAD > 0 for e in es) >= len(es) * 3 // 4
    assert sim.sender.stats()["packets"]["cut_sent"] == sim.receiver.stats()["packets"]["cut_joined"]


def test_an_entry_with_cut_false_is_never_cut():
    sim = saturated(LinkPolicy(queue="fifo", depth=100, cut=False))
    assert not any(m.cut for e in envelopes(sim) for m in e.messages)
    assert len(sim.received) == 60


def test_reliable_entries_are_never_cut():
    sim = saturated(replace(LinkPolicy(queue="fifo", depth=100), reliable=True))
    assert not any(m.cut for e in envelopes(sim) for m in e.messages)


@given(st.integers(0, 10_000))
@settings(max_examples=10, deadline=None)
def test_with_loss_a_cut_message_arrives_whole_or_not_at_all_and_order_is_kept(seed):
    sim = saturated(LinkPolicy(queue="fifo", depth=100), per=0.2, seed=seed)
    got = [p for _, p in sim.received]
    sent = {bytes((0, 5)) + i.to_bytes(2, "big") + bytes(28) for i in range(60)}
    assert set(got) <= sent and len(got) == len(set(got))
    serials = [int.from_bytes(p[2:4], "big") for p in got]
    assert serials == sorted(serials)
    rx = sim.receiver.stats()["packets"]
    assert rx["cut_joined"] + rx["cut_orphan"] >= 1


def test_the_packet_of_a_transfers_last_fragment_is_filled_with_other_traffic():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, sender_id=1, fragment_id=250,
                  rng=random.Random(3))
    for key, policy in ((7, LinkPolicy(queue="fifo", depth=10, priority=5)),
                        (5, LinkPolicy(queue="fifo", depth=100))):
        sim.sender.add_channel(key, policy)
    sim.sender.offer(7, bytes((0, 7)) + bytes(80))           # two fragments at 64 B
    for i in range(20):
        sim.sender.offer(5, bytes((0, 5)) + i.to_bytes(2, "big") + bytes(28))
    sim.run(6.0)
    es = envelopes(sim)
    last = next(e for e in es if any(m.kind == env.FRAGMENT and m.body[1] == m.body[2] - 1
                                     for m in e.messages))
    assert len(last.encode()) == 63 and len(last.messages) > 1   # the fragment and more
    assert bytes((0, 7)) + bytes(80) in [p for _, p in sim.received]


def test_an_entry_with_a_max_age_is_never_cut():
    # its age is judged against T of the packet that carries the message: a cut one would be
    # judged by the wrong packet's T
    from uwgen.runtime.clock import ManualClock
    from uwgen.runtime.delivery.reliability import Reliability
    from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, message_measure
    from uwgen.runtime.link.scheduler import LinkScheduler
    from uwgen.runtime.stats import Counters
    clock = ManualClock()
    hooks = Reliability(1, period=0.2, reliable={}, max_ages={5: 30.0}, wall=clock,
                        max_read_length=64).hooks()
    s = LinkScheduler(clock, measure=message_measure, stamp=hooks.stamp, overhead=hooks.head_room)
    for key in (4, 5):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=100))
        for i in range(20):
            s.offer(key, bytes((0, key)) + i.to_bytes(2, "big") + bytes(28))
    packer = Packer(s, sender=1, max_read_length=64, hooks=hooks, counters=Counters(PACKET_COUNTERS))
    cuts = [m for _ in range(12) for m in env.decode(packer.next_packet(clock.now())).messages
            if m.kind & env.CUT_HEAD]
    assert cuts and {m.id for m in cuts} == {4}


def test_on_a_sealed_link_an_encrypted_message_is_cut_sealed_and_joined():
    from tests.security.helpers import twist
    from tests.security.test_packet_link import packets, sealed_sim
    sim, _tx, rx = sealed_sim()
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=200))     # id 4 is encrypt
    sent = [twist(float(i)) for i in range(40)]
    for p in sent:
        sim.sender.offer(4, p)
    sim.run(20.0)
    assert [p for _, p in sim.received] == sent
    frames = packets(sim)
    heads = [m for f in frames for m in env.decode(f).messages if m.kind & env.CUT_HEAD]
    assert heads and sim.receiver.stats()["packets"]["cut_joined"] == len(heads)
    assert rx.stats()["verified"] == len(frames)
    assert all(p[2:12] not in f for p in sent for f in frames)          # never in the clear


def test_the_tail_of_the_last_message_cut_wakes_the_connection_for_the_next_packet():
    sim = LinkSim(scenario(), "a", "b", wire_format=2, sender_id=1)
    sim.sender.add_channel(5, LinkPolicy(queue="fifo", depth=100))
    for i in range(2):
        sim.sender.offer(5, bytes((0, 5)) + i.to_bytes(2, "big") + bytes(28))
    assert sim.sender.packer.next_packet(0.0) is not None          # one whole, one cut
    assert sim.sender.scheduler.next_ready_time(0.0) is None       # nothing queued...
    assert sim.sender._next_ready(0.5) == 0.5                       # ...but the tail must go
    assert sim.sender._backlog(0.5, sim.sender.hooks)


def test_the_hooks_are_told_the_tail_takes_room_but_not_that_it_was_sent_again():
    # reliability sizes its A part from what `carrying` says the messages take
    from uwgen.runtime.link.hooks import PacketHooks
    carried, sent = [], []
    hooks = PacketHooks(carrying=lambda picked, now, fresh: carried.append(list(picked)),
                        sent=lambda n, picked, now: sent.append(list(picked)))
    sim = LinkSim(scenario(), "a", "b", wire_format=2, sender_id=1, hooks=hooks)
    sim.sender.add_channel(5, LinkPolicy(queue="fifo", depth=100))
    for i in range(3):
        sim.sender.offer(5, bytes((0, 5)) + i.to_bytes(2, "big") + bytes(28))
    first, second = (env.decode(sim.sender.packer.next_packet(t)) for t in (0.0, 0.2))
    assert second.messages[0].kind == env.CUT_TAIL
    assert carried[1][0] == (5, env.to_v1(second.messages[0]))
    assert len(env.encode_messages([env.from_v1(p) for _, p in carried[1]])) == \
        len(env.encode_messages(second.messages))
    assert [len(s) for s in sent] == [2, 1]           # each message is sent in one list
