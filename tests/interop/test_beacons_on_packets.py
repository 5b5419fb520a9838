"""Beacons with packet-aligned writes: no other frame shares a packet with a beacon."""
from __future__ import annotations

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.interop.discovery import DiscoveryAgent, bridge_beacons, discovery_policies
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire.framing import encode_frame


def test_a_beacon_round_beside_a_command_stream_shares_no_packet(rmw_manifest):
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=0.2, max_read_length=64, bitrate=4800.0)
    sim = LinkSim(scen, "a", "b")
    beacons = bridge_beacons(rmw_manifest, "surface")
    for key, policy in discovery_policies(len(beacons)).items():
        sim.sender.add_channel(key, policy)
    sim.sender.add_channel(4, LinkPolicy(queue="fifo", depth=100))
    agent = DiscoveryAgent(beacons, send=sim.sender.offer, queued=lambda: sim.sender.queued(1))
    for i in range(40):
        sim.at(i * 0.1, lambda i=i: sim.sender.offer(4, bytes([0, 4, i]) + bytes(17)))
    sim.at(0.55, agent.start)
    sim.at(0.56, lambda: agent.handle(b"\x00\x02"))     # a request while the round waits: no 2nd round
    sim.run(15.0)
    stream = b"".join(d.data for d in sim.packets)
    starts, pos = [], 0
    for d in sim.packets:
        starts.append((pos, pos + len(d.data)))
        pos += len(d.data)
    frames = [encode_frame(p) for _, p in sim.received if p[:2] == b"\x00\x01"]
    assert len(frames) == len(beacons) == 3 and agent.stats()["rounds_skipped"] == 1
    for frame in frames:
        lo = stream.index(frame)
        hi = lo + len(frame)
        touching = [(a, b) for a, b in starts if a < hi and b > lo]
        assert len(touching) == 2                       # 83 bytes: two packets, nobody else's bytes
        assert touching[0][0] == lo and touching[-1][1] == hi
