"""Delivery toward an rmw_desert receiver through the emulated channel, before and after alignment.

    .venv/bin/python benchmarks/rmw_peer_bench.py [--seconds 300] [--seeds 3]

A surface bridge's link (profile rmw_desert: no fragments) sends, over 64-byte packets every
0.2 s, what the turtlesim teleoperation sends: Twist commands (5 Hz, `latest`), a 1 Hz
std_msgs/String status line of 30-50 characters, and a round of discovery beacons for its three
entities every 10 s (as if a discovery request came). Payloads are built by the independent
rmw_desert peer (tests/peers/rmw_desert_peer.py) from real rclpy messages; the emulator core
loses packets at the given PER; the peer's parsers read what arrives:

- "peer": the independent peer's FrameHunter (resyncs after a mismatch, one byte on);
- "strict": rmw_desert's parser as observed on real DESERT (after `99 99 LEN` it takes LEN + 1
  bytes whatever they hold, and drops them all when the last is not 0x55: it cannot resync
  inside a frame).

"before": cut-and-fill writes and the old gids (hash bytes, up to 2 CBOR bytes each); "after":
packet-aligned writes and base-24 gids (beacons 14 bytes shorter); "echo": "after", and the last
piece of a beacon cut over two packets repeated at the start of the next write
(uwgen.runtime.link.pacing), so a lost tail no longer takes the next packet's frames with it.
Figures: delivered / sent, per kind, summed over the seeds.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import random
import sys
from pathlib import Path

from geometry_msgs.msg import Twist
from std_msgs.msg import String

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.interop.beacons import Beacon, Entity, derive_gid, encode_beacon
from uwgen.interop.discovery import discovery_policies
from uwgen.manifest.model import LinkPolicy

ROOT = Path(__file__).resolve().parents[1]
CMD, STATUS = 4, 6


def load_peer():
    spec = importlib.util.spec_from_file_location("rmw_desert_peer", ROOT / "tests" / "peers" / "rmw_desert_peer.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["rmw_desert_peer"] = module
    spec.loader.exec_module(module)
    return module


class StrictHunter:
    """rmw_desert's parser as the issue describes it: no resync inside a frame."""

    def __init__(self):
        self.buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        self.buf += data
        out = []
        while True:
            start = self.buf.find(b"\x99\x99")
            if start < 0:
                del self.buf[:max(0, len(self.buf) - 1)]
                return out
            del self.buf[:start]
            if len(self.buf) < 3:
                return out
            n = self.buf[2]
            if len(self.buf) < 4 + n:
                return out
            if n and self.buf[3 + n] == 0x55:
                out.append(bytes(self.buf[3:3 + n]))
            del self.buf[:4 + n]           # a bad frame takes all its LEN + 4 bytes with it


def beacons(new_gids: bool) -> list[bytes]:
    entries = [(Entity.PUBLISHER, "/turtle1/cmd_vel", "geometry_msgs__msg/Twist"),
               (Entity.SUBSCRIBER, "/turtle1/pose", "turtlesim__msg/Pose"),
               (Entity.CLIENT, "/turtle1/teleport_absolute", "turtlesim__srv/TeleportAbsolute_Request")]
    out = []
    for entity, topic, type_name in entries:
        if new_gids:
            gid = derive_gid("turtle_rmw", "surface", entity, topic)
        else:
            key = "\x00".join(("uwgen-gid-v1", "turtle_rmw", "surface", str(int(entity)), topic))
            gid = hashlib.sha256(key.encode()).digest()[:16]
        out.append(encode_beacon(Beacon("uwgen_surface", "/", entity, gid, topic, type_name)))
    return out


def run(peer, per: float, seed: int, seconds: float, mode: str) -> dict[str, tuple[int, int, int]]:
    after = mode != "before"
    scenario = Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                               NodeSpec("vehicle", position=(300, 0, 0), dest="surface")],
                        period=0.2, max_read_length=64, per=per, seed=seed, bitrate=4800.0)
    sim = LinkSim(scenario, "surface", "vehicle", aligned=after)
    link = sim.sender
    link.connection.outbox.echo = mode == "echo"
    rounds = beacons(new_gids=after)
    for key, policy in discovery_policies(len(rounds)).items():
        link.add_channel(key, policy)
    link.add_channel(CMD, LinkPolicy(queue="latest", rate=5, ttl=1.0, priority=10))
    link.add_channel(STATUS, LinkPolicy(queue="fifo", depth=10, priority=5))
    rng = random.Random(seed)
    sent = {"twist": 0, "status": 0, "beacon": 0}

    def cmd():
        m = Twist()
        m.linear.x, m.angular.z = rng.choice([0.0, 1.0, 2.0, -1.5]), rng.uniform(-2, 2)
        if link.offer(CMD, peer.topic_payload(CMD, m)):
            sent["twist"] += 1

    def status(i):
        m = String()
        m.data = f"battery {rng.uniform(20, 100):.1f} % depth {rng.uniform(0, 50):.2f} m #{i}"[:rng.randint(30, 50)]
        link.offer(STATUS, peer.topic_payload(STATUS, m))
        sent["status"] += 1

    def announce():
        for b in rounds:
            link.offer(1, b)
            sent["beacon"] += 1

    for i in range(int(seconds * 5)):
        sim.at(i * 0.2 + 0.01, cmd)
    for i in range(int(seconds)):
        sim.at(i + 0.37, lambda i=i: status(i))
    for i in range(int(seconds / 10)):
        sim.at(i * 10 + 0.05, announce)
    sim.run(seconds + 5)
    # Twist commands superseded in our own queue never left: count what the link sent.
    sent["twist"] = link.scheduler.stats()[CMD]["sent"]
    out = {}
    for parser in ("peer", "strict"):
        hunter = peer.FrameHunter() if parser == "peer" else StrictHunter()
        got = {"twist": 0, "status": 0, "beacon": 0}
        for d in sim.packets:
            for payload in hunter.feed(d.data):
                try:
                    kind, ident, _, items, _ = peer.split_header(payload)
                    if ident == 1:
                        peer.parse_beacon(items)
                        got["beacon"] += 1
                    elif ident == CMD:
                        peer.decode_topic(payload, Twist)
                        got["twist"] += 1
                    elif ident == STATUS:
                        peer.decode_topic(payload, String)
                        got["status"] += 1
                except peer.PeerError:
                    pass
        out[parser] = got
    return {k: (sent[k], out["peer"][k], out["strict"][k]) for k in sent}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=300.0)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--per", type=float, nargs="*", default=[0.05, 0.10, 0.20])
    a = ap.parse_args()
    peer = load_peer()
    print(f"toward an rmw_desert receiver: 64 B / 0.2 s, {a.seconds:.0f} s x {a.seeds} seeds; "
          "delivered / sent (peer parser | strict rmw_desert parser)")
    modes = ("before", "after", "echo")
    head = f"{'PER':>5}  {'kind':<8}" + "".join(f"{m + ' peer':>13}" for m in modes) \
        + "".join(f"{m + ' strict':>15}" for m in modes)
    print(head)
    print("-" * len(head))
    for per in a.per:
        totals = {m: {} for m in modes}
        for mode in modes:
            for seed in range(a.seeds):
                for kind, (s, p, st) in run(peer, per, seed, a.seconds, mode).items():
                    t = totals[mode].setdefault(kind, [0, 0, 0])
                    t[0] += s
                    t[1] += p
                    t[2] += st
        for kind in ("twist", "status", "beacon"):
            row = [totals[m][kind] for m in modes]
            print(f"{per:>5.0%}  {kind:<8}" + "".join(f"{r[1] / r[0]:>13.1%}" for r in row)
                  + "".join(f"{r[2] / r[0]:>15.1%}" for r in row))


if __name__ == "__main__":
    main()
