"""Links of wire format 2 sealed per packet, over the emulator's lossy core (simulated time):
fragments of an encrypted message, loss, and a receiver that starts late."""
from __future__ import annotations

import random

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.framing import ShortFrameDecoder
from uwgen.runtime.link.link import Link
from uwgen.runtime.link.hooks import join_hooks
from uwgen.security.packet_seal import PacketSeal

from .helpers import KEY, WALL0, config, twist

FRAGMENT_ID = 250


def sealed_sim(per: float = 0.0, seed: int = 1) -> tuple[LinkSim, PacketSeal, PacketSeal]:
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=64, per=per, seed=seed, bitrate=4800.0)
    wall = ManualClock(WALL0)
    tx = PacketSeal(KEY, config(1, 2, "vehicle"), fragment_id=FRAGMENT_ID, wall=wall, name="surface")
    rx = PacketSeal(KEY, config(2, 1, "surface"), fragment_id=FRAGMENT_ID, wall=wall, name="vehicle")
    sim = LinkSim(scen, "a", "b", wire_format=2, sender_id=1, fragment_id=FRAGMENT_ID,
                  rng=random.Random(seed), hooks=join_hooks(tx.hooks()))
    tx.clock = rx.clock = sim.clock
    sim.receiver = Link(config=LinkConfig(max_read_length=64, period=0.2), clock=sim.clock, name="b",
                        wire_format=2, sender_id=2, fragment_id=FRAGMENT_ID, hooks=join_hooks(rx.hooks()),
                        on_payload=lambda p: sim.received.append((sim.clock.now(), p)))
    return sim, tx, rx


def packets(sim: LinkSim) -> list[bytes]:
    return [f for d in sim.packets for f in ShortFrameDecoder().feed(d.data)]


def test_an_encrypted_message_in_fragments_is_sealed_in_every_packet_and_arrives_whole():
    sim, tx, rx = sealed_sim()
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=4))
    big = bytes((0, 4)) + random.Random(3).randbytes(400)          # id 4 is encrypt
    sim.sender.offer(4, big)
    sim.run(6.0)
    assert [p for _, p in sim.received] == [big]
    frames = packets(sim)
    assert len(frames) > 5 and all(env.decode(f).sealed for f in frames)
    assert all(big[k:k + 16] not in f for f in frames for k in range(2, len(big) - 16, 16))
    assert all(len(d.data) <= 64 for d in sim.packets)
    assert rx.stats()["verified"] == len(frames) and rx.stats()["dropped"] == 0


def test_with_loss_every_packet_that_arrives_is_verified_and_nothing_else_delivered():
    sim, tx, rx = sealed_sim(per=0.3, seed=4)
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=200))
    sent = [twist(float(i)) for i in range(150)]
    for i, p in enumerate(sent):
        sim.at(0.1 * i, lambda p=p: sim.sender.offer(4, p))
    sim.run(40.0)
    got = [p for _, p in sim.received]
    assert got and set(got) <= set(sent) and len(got) == len(set(got))
    st = rx.stats()
    # the packets lost before the first sync packet that arrived are the only ones not taken
    assert st["verified"] + st["unsynced"] == len(sim.packets) and st["dropped"] == st["unsynced"]
