#!/usr/bin/env python3
"""Wire format 2 against wire format 1, same run: air bytes per message, link use, shares.

    .venv/bin/python benchmarks/envelope_bench.py [--seconds 300]

Each run drives real uwgen Links (scheduler, fragments, security guard, pacer and Outbox) on
simulated time: every write the sender's connection would make goes, lossless, into the
receiver's decoder. Air bytes count each packet as DESERT sends it: the bytes written plus the
4 bytes of UDP and IP header DESERT adds (docs/wire-format.md section 1).

Table 0, the demo's mix as bridges send it: both directions at once on one pair of links, each
with the hooks a bridge gives it (reliability, and the per-packet seal with the 8-byte tag when
secured), so acknowledgements and the clock offset's exchange flow; air bytes per delivered
message against a baseline commit's code (`--baseline`, `main` for the branch's start), and
what they carry part by part (DESERT, frame, P, W, K, T, A, C, message heads, the reliability
heads N and age, tag, body; docs/wire-format.md section 14.3). Goals: 15 unsecured, 21 secured.
Table 0b, the same mix as the demo runs it: under its manifest's MAC (turns: the surface grants
each side 2 packets a turn; the emulator's core carries the packets, envelope_turns), beside
the row without a MAC above, same run: per delivered message and part by part (C: the MAC's
grants and ends), messages delivered per topic, refused stale, the MAC's turns.

Table 1, the demo's mix, secured as the demo is (docs/demo.md): cmd_vel published at 10 Hz
(encrypted, packed, rate 5), pose at 10 Hz (signed, packed, rate 2), battery at 1 Hz (signed,
rate 0.2), 8 log lines every 20 s (not protected), an encrypted teleport request every 30 s, and
each side's schema announcement (signed) at start; real messages through the demo package's
codecs. Air bytes per delivered message, both directions; goal: wire format 2 <= half of 1.
Wire format 2 is sealed as a bridge seals it: one tag per packet (PacketSeal, wire-format.md 12.2) when
that is on the branch, else per message; with the default 8-byte tag, and again with the
6- and 4-byte tags the manifest's `security: {tag_bytes}` offers (docs/security.md weighs them). Then what those bytes carry, per delivered message:
DESERT's 4 bytes per packet, frames, packet heads (P, W, parts but the tag), message heads (kind
and id items; H, id and length bytes), security (per message: what the receiver's guard took
off; per packet: the tag) and the rest of the bodies.

Table 2, link use under saturation (bytes written per second / (max_read_length / period)):
FIFO channels always full, latest-only channels with a fresh message before every write, and a
mix of both. Goal: >= 0.9 each with wire format 2. Use is fill x pace: `fill` is the mean write
over max_read_length (what packing leaves empty), `pace` the writes per period (the pacer's 5 %
margin caps it at 1 / 1.05 = 0.952; DESERT sends one packet per period whatever its size).

Table 3, shares of a saturated link with one unrated priority-10 topic and 49 priority-0 topics
(all flooding): before (strict priority, what the scheduler did before wire format 2) and after
(claims growing with waiting time; a share in proportion to priority + 1).

Table 4: one large message alone (400 and 2000 bytes, with and without repair fragments):
packets and bytes written with wire format 1 fragments and wire format 2 compact fragments.
"""
from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path

from uwgen.bridge.schema import encode_announcements
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire import envelope
from uwgen.runtime.link.link import Link

from envelope_parts import DESERT_HEADER, SimWall, air_parts, baseline, breakdown, counting_heads, print_table0
from envelope_turns import mac_kw, merge, outcome, print_turns, run_on_core
from uwgen.security.guard import GuardConfig, LinkGuard

try:            # the per-packet seal (wire-format 12.2): what a bridge uses on wire format 2 links
    from uwgen.security.packet_seal import PacketSeal
except ImportError:     # not on this branch yet: wire format 2 is sealed per message
    PacketSeal = None

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "generated"))
import uwgen_demo as demo  # noqa: E402  (the demo's generated package)
from uwgen_demo.geometry_msgs.msg import Twist, Vector3  # noqa: E402
from uwgen_demo.sensor_msgs.msg import BatteryState  # noqa: E402
from uwgen_demo.std_msgs.msg import String  # noqa: E402
from uwgen_demo.turtlesim.msg import Pose  # noqa: E402
from uwgen_demo.turtlesim.srv import TeleportAbsolute_Request  # noqa: E402

CONFIG = LinkConfig(max_read_length=64, period=0.2)
MASTER = bytes(range(32))
SENDERS = {"surface": 1, "vehicle": 2}
MODES = {4: "encrypt", 5: "sign", 6: "sign", 20: "encrypt", 21: "encrypt", 30: "encrypt", 249: "sign"}


class Pair:
    """A sending Link and a receiving Link on one ManualClock; `run` plays the writes."""

    def __init__(self, wire: int, src: str = "a", dst: str = "b", *, secure_dir: Path | None = None,
                 packed: frozenset[int] = frozenset(), fragment_id: int | None = 250,
                 tag_bytes: int = envelope.TAG_LEN, bridge: bool = False, turns: bool = False):
        """`bridge`: the demo's sides with the hooks a bridge gives its link (reliability,
        joined with the seal when secured: uwgen.bridge.node), both of them sending (`run`
        carries each side's writes to the other, so acknowledgements and the clock offset's
        exchange flow as between real bridges); their wall clock follows the simulation's.
        `turns`: each side with the demo manifest's MAC, through the emulator's core
        (envelope_turns)."""
        self.clock = ManualClock()
        self.two_way = bridge and wire == 2
        wall = SimWall(self.clock)
        self.message_items = 0     # bytes of reliability heads (N, age) the receiver took off
        self.delivered: list[bytes] = []
        self.air = 0
        self.packets = 0
        self.written = 0
        self.macs, self.rel, self.seals = {}, {}, {}
        kw = dict(config=CONFIG, clock=self.clock, fragment_id=fragment_id, rng=random.Random(1))
        if wire == 2:
            kw.update(wire_format=2, packed_ids=packed)
        guards, seals = {}, self.seals
        if secure_dir is not None:
            for side, other in ((src, dst), (dst, src)):
                cfg = GuardConfig("demo", SENDERS[side], {SENDERS[other]: other}, MODES,
                                  **({"tag_bytes": tag_bytes} if wire == 2 else {}))
                lock = secure_dir / f"{wire}-{tag_bytes}-{src}{dst}-{side}.lock"
                if wire == 2 and PacketSeal is not None:    # as a bridge does: one tag a packet
                    seals[side] = PacketSeal.for_key(MASTER, cfg, lock, clock=self.clock, name=side,
                                                     fragment_id=fragment_id,
                                                     **({"wall": wall} if self.two_way else {}))
                else:
                    guards[side] = LinkGuard.for_key(MASTER, cfg, lock, clock=self.clock, name=side)
        if wire == 2:
            kw_src = dict(kw, sender_id=SENDERS.get(src, 0))
        else:
            kw_src = kw
        hooks = {side: seals[side].hooks() for side in seals}
        if bridge and wire == 2:
            from uwgen.bridge.plan import BridgePlan
            from uwgen.bridge.reliability import reliability_for
            try:
                from uwgen.runtime.link.hooks import join_hooks
            except ImportError:     # a baseline build (--baseline): in the packer's module
                from uwgen.runtime.link.packets import join_hooks
            for side in (src, dst):
                plan = BridgePlan.from_package(demo, side)
                seal = hooks.get(side)
                over = seal.overhead if seal is not None else 0
                rel = self.rel[side] = reliability_for(   # T on the wall clock, as the seal's
                    plan, CONFIG, wall, **(mac_kw(self, plan, side, CONFIG, over) if turns
                                           else {"other_overhead": over}))
                hooks[side] = join_hooks(rel.hooks(), seal)
                hooks[side] = counting_heads(self, hooks[side])
        self.returned: list[bytes] = []     # what the sender receives (two_way)
        macs = {side: {"mac": m} for side, m in self.macs.items()}
        self.sender = Link(name=src, **({"guard": guards[src]} if guards else {}), **macs.get(src, {}),
                           **({"hooks": hooks[src]} if src in hooks else {}), **kw_src,
                           **({"on_payload": self.returned.append} if self.two_way else {}))
        if self.two_way:
            kw = dict(kw, sender_id=SENDERS.get(dst, 0))
        self.receiver = Link(name=dst, on_payload=self.delivered.append, **macs.get(dst, {}),
                             **({"guard": guards[dst]} if guards else {}),
                             **({"hooks": hooks[dst]} if dst in hooks else {}), **kw)
        self.wire, self.tag_bytes = wire, tag_bytes
        self.batches: list[bytes] = []
        self.security = 0          # bytes protection added to the messages received
        if guards:
            unprotect = self.receiver.guard.unprotect

            def counted(payload: bytes) -> bytes | None:
                plain = unprotect(payload)
                if plain is not None:
                    self.security += len(payload) - len(plain)
                return plain
            self.receiver.guard.unprotect = counted

    def breakdown(self) -> dict[str, int]:
        """Air bytes by what they carry (table 1: envelope_parts.breakdown)."""
        return breakdown(self.batches, self.wire, self.tag_bytes, self.security)

    def parts(self) -> dict[str, int]:
        """Air bytes of wire format 2+ by part (table 0's breakdown: envelope_parts.air_parts)."""
        return air_parts(self.batches, self.tag_bytes, self.message_items)

    def run(self, seconds: float, before_write=None) -> None:
        if self.macs:
            return run_on_core(self, seconds, before_write, CONFIG)
        conn, rx = self.sender.connection, self.receiver.connection
        box = conn.outbox
        ways = [(conn, rx)] + ([(rx, conn)] if self.two_way else [])
        t = 0.0
        while t <= seconds:
            self.clock.set(t)
            if before_write is not None:
                before_write(t)
            for tx, to in ways:
                batch = tx.outbox.take(t, tx._pull, tx._fit)
                if batch:
                    tx.outbox.sent(t)
                    self.batches.append(batch)
                    self.packets += 1
                    self.written += len(batch)
                    self.air += len(batch) + DESERT_HEADER
                    to._deliver(to.decoder.feed(batch))
            self.receiver._tick(t)
            if self.two_way:
                self.sender._tick(t)
            nxt = min(tx.outbox.pacer.next_write_at for tx, _ in ways)
            t = round(max(t + CONFIG.period / 16, nxt) if before_write is None else max(nxt, t + 1e-3), 9)


# -- table 1: the demo's mix ------------------------------------------------------------------

def twist(k: int) -> Twist:
    return Twist(linear=Vector3(x=0.3 + 0.01 * (k % 50), y=0.0, z=float(k % 65536)),
                 angular=Vector3(x=0.0, y=0.0, z=0.1 * (k % 7) - 0.3))


def pose(k: int) -> Pose:
    return Pose(x=5.5 + 0.01 * (k % 100), y=5.0 - 0.01 * (k % 80), theta=0.001 * (k % 3000) - 1.5,
                linear_velocity=0.4, angular_velocity=0.1)


def battery(k: int) -> BatteryState:
    b = BatteryState()
    b.voltage, b.current, b.percentage = 15.2 - 0.001 * k, -1.5, 0.9 - 0.0001 * k
    b.power_supply_status, b.present = 2, True
    return b


def demo_mix(wire: int, seconds: float, tmp: Path | None,
             tag_bytes: int = envelope.TAG_LEN, bridge: bool = False, turns: bool = False,
             seen: dict | None = None) -> tuple[int, int, dict[str, int]]:
    """Air bytes, delivered messages and the air bytes' breakdown of both directions of the
    demo's traffic (`tmp` None: unsecured). `bridge`: with a bridge's reliability hooks, both
    directions on one pair of links at once, as between real bridges (each side's packets
    carry the acknowledgements of the other's); else each direction alone. `turns`: under
    the demo manifest's MAC; `seen`: filled with envelope_turns.outcome (and packets)."""
    air = delivered = 0
    parts: dict[str, int] = {}
    packed = frozenset(i for i, c in {**demo.TOPICS, **demo.SERVICES}.items() if c.profile == "packed")
    ways = [("surface", "vehicle")] if bridge and wire == 2 else [("surface", "vehicle"), ("vehicle", "surface")]
    for src, dst in ways:
        pair = Pair(wire, src, dst, secure_dir=tmp, packed=packed, tag_bytes=tag_bytes,
                    bridge=bridge, turns=turns)
        sides = [(pair.sender, src)] + ([(pair.receiver, dst)] if pair.two_way else [])
        events = sorted((e for link, side in sides for e in load(pair, link, side, seconds)),
                        key=lambda e: e[0])
        pending = iter(events)
        nxt = [next(pending, None)]

        def offers(now: float) -> None:
            while nxt[0] is not None and nxt[0][0] <= now:
                _, link, key, payload = nxt[0]
                link.offer(key, payload)
                nxt[0] = next(pending, None)

        pair.run(seconds, offers)
        air += pair.air
        if seen is not None:
            merge(seen, {**outcome(pair), "packets": pair.packets})
        delivered += sum(1 for p in pair.delivered + pair.returned
                         if p[1] != 249 and not p.startswith(b"\x00\x18\xf9"))
        for k, v in (pair.parts() if bridge else pair.breakdown()).items():
            parts[k] = parts.get(k, 0) + v
    assert sum(parts.values()) == air, (parts, air)
    return air, delivered, parts


def load(pair: Pair, link: Link, side: str, seconds: float) -> list[tuple[float, Link, int, bytes]]:
    """Give `link` the demo's channels of `side` and its announcements; its offers, in time."""
    t = demo.TOPICS
    fingerprints = [(i, c.fingerprint) for i, c in sorted({**t, **demo.SERVICES}.items())]
    link.add_channel(249, LinkPolicy(queue="fifo", depth=4, priority=11, strict=True))
    # split as the bridge splits them: each leaves whole in one packet
    for p in encode_announcements(249, fingerprints, request=True,
                                  max_payload=link.whole_payload(249)):
        pair.clock.set(0.0)
        link.offer(249, p)
    events: list[tuple[float, Link, int, bytes]] = []
    if side == "surface":
        link.add_channel(4, t[4].policy)
        link.add_channel(20, demo.SERVICES[20].policy)
        events += [(k * 0.1, link, 4, t[4].encode(twist(k))) for k in range(int(seconds * 10))]
        req = demo.SERVICES[20].encode_request(7, TeleportAbsolute_Request(x=5.5, y=5.5, theta=0.0))
        events += [(k * 30.0 + 1.0, link, 20, req) for k in range(int(seconds / 30))]
    else:
        for key in (5, 6, 7):
            link.add_channel(key, t[key].policy)
        events += [(k * 0.1, link, 5, t[5].encode(pose(k))) for k in range(int(seconds * 10))]
        events += [(k * 1.0, link, 6, t[6].encode(battery(k))) for k in range(int(seconds))]
        events += [(k * 20.0 + 0.5, link, 7, t[7].encode(String(data=f"mission step {k}: depth 12.{j} m ok")))
                   for k in range(int(seconds / 20)) for j in range(8)]
    return events


# -- table 2: link use under saturation -------------------------------------------------------

def head(key: int) -> bytes:
    """CBOR kind 0 and id `key` (shortest form), the start of a wire format 1 topic payload."""
    return bytes((0, key)) if key < 24 else bytes((0, 0x18, key))


SIZES = (6, 8, 11, 14, 19, 22, 27, 37)     # wire format 1 payloads of the demo (packed, signed...)


def saturated(wire: int, kind: str, seconds: float) -> tuple[float, float, float]:
    """(link use, fill, pace) of one saturated run."""
    pair = Pair(wire, fragment_id=250)
    link = pair.sender
    fifo = {"fifo": SIZES[:4], "latest": (), "mixed": SIZES[:2]}[kind]
    latest = {"fifo": (), "latest": SIZES, "mixed": SIZES[2:]}[kind]
    keys = {}
    for n, size in enumerate(fifo):
        keys[10 + n] = ("fifo", size)
        link.add_channel(10 + n, LinkPolicy(queue="fifo", depth=100_000))
    for n, size in enumerate(latest):
        keys[14 + n] = ("latest", size)
        link.add_channel(14 + n, LinkPolicy(queue="latest"))
    count = [0]

    def top_up(now: float) -> None:
        for key, (q, size) in keys.items():
            if q == "latest" or link.queued(key) < 50:
                for _ in range(1 if q == "latest" else 50):
                    count[0] += 1
                    link.offer(key, head(key) + count[0].to_bytes(4, "big") + bytes(size - 4 - len(head(key))))

    pair.run(seconds, top_up)
    periods = seconds / CONFIG.period
    return (pair.written / (periods * CONFIG.max_read_length),
            pair.written / pair.packets / CONFIG.max_read_length, pair.packets / periods)


# -- table 3: shares per priority -------------------------------------------------------------

def shares(strict: bool, seconds: float) -> dict[str, float]:
    pair = Pair(2, fragment_id=None)
    link = pair.sender
    link.add_channel(1, LinkPolicy(queue="fifo", depth=100_000, priority=10, strict=strict))
    for key in range(2, 51):
        link.add_channel(key, LinkPolicy(queue="fifo", depth=1000, priority=0, strict=strict))

    def top_up(now: float) -> None:
        for key in range(1, 51):
            while link.queued(key) < 20:
                link.offer(key, head(key) + bytes((1, 2, 3, 4)))

    pair.run(seconds, top_up)
    counts = {k: 0 for k in range(1, 51)}
    for p in pair.delivered:
        counts[p[1] if p[1] < 24 else p[2]] += 1
    total = sum(counts.values())
    others = [counts[k] / total for k in range(2, 51)]
    return {"top": counts[1] / total, "others": sum(others), "min_other": min(others),
            "starved": sum(1 for k in range(2, 51) if counts[k] == 0), "messages": total}


# -- table 4: fragments --------------------------------------------------------------------

def fragments(wire: int, size: int, repair: int = 0) -> tuple[int, int, bool]:
    """(packets, bytes written, delivered) for one `size`-byte message sent alone."""
    pair = Pair(wire, fragment_id=250)
    pair.sender.add_channel(7, LinkPolicy(queue="fifo", depth=4, repair=repair))
    payload = head(7) + random.Random(size).randbytes(size - 2)
    pair.sender.offer(7, payload)
    pair.run(size / 40 * CONFIG.period + 5.0)
    return pair.packets, pair.written, pair.delivered == [payload]


def as_deployed(seconds: float, turns: bool = False, detail: bool = False) -> dict[str, float]:
    """Air bytes per delivered message of the demo's mix as the bridges send it (their
    reliability hooks, the per-packet seal with the 8-byte tag when secured); `turns`: under
    the demo manifest's MAC; `detail`: with messages, packets and envelope_turns.outcome."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, secure in (("unsecured", None), ("secured", Path(tmp))):
            seen = {} if detail else None
            air, n, parts = demo_mix(2, seconds, secure, envelope.TAG_LEN, bridge=True,
                                     turns=turns, seen=seen)
            out[label] = air / n
            out[label + " parts"] = {k: v / n for k, v in parts.items()}
            if detail:
                out[label + " messages"], out[label + " packets"] = n, seen.pop("packets")
                out[label + " outcome"] = seen
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=300.0, help="simulated seconds per run")
    parser.add_argument("--baseline", default="a7c9504",
                        help="commit whose code table 0 compares with (`none`: skip table 0)")
    parser.add_argument("--deployed-json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    s = args.seconds
    if args.deployed_json:
        import json
        print(json.dumps(as_deployed(s)))
        return
    if args.baseline != "none":
        base, now = baseline(Path(__file__).resolve(), ROOT, args.baseline, s), as_deployed(s, detail=True)
        print_table0(args.baseline, base, now)
        print_turns({"no MAC": now, "turns": as_deployed(s, turns=True, detail=True)}, s)

    print("Table 1: the demo's mix, secured: air bytes per delivered message (both directions); "
          f"wire format 2 sealed {'per packet (PacketSeal)' if PacketSeal else 'per message (LinkGuard)'}")
    print(f"{'wire format':<18}{'air bytes':>10}{'messages':>10}{'bytes/msg':>11}{'/ wf 1':>8}")
    rows, split = {}, {}
    runs = {"1": (1, 8), "2": (2, 8)}
    if PacketSeal is not None:      # the manifest's shorter tags (security: {tag_bytes})
        runs.update({"2, 6-byte tag": (2, 6), "2, 4-byte tag": (2, 4)})
    with tempfile.TemporaryDirectory() as tmp:
        for label, (wire, tag) in runs.items():
            air, n, split[label] = demo_mix(wire, s, Path(tmp), tag)
            rows[label] = air / n
            print(f"{label:<18}{air:>10}{n:>10}{air / n:>11.1f}{rows[label] / rows['1']:>8.2f}")
    ratio = rows["2"] / rows["1"]
    print(f"wire format 2 / 1: {ratio:.2f}  (goal <= 0.5: {'ok' if ratio <= 0.5 else 'MISS'})")
    print("what the air bytes per delivered message carry:")
    print(f"{'wire format':<18}" + "".join(f"{k:>14}" for k in split["1"]))
    for label in runs:
        n = sum(split[label].values()) / rows[label]
        print(f"{label:<18}" + "".join(f"{v / n:>14.1f}" for v in split[label].values()))
    print()
    print("Table 2: link use under saturation (bytes written / (max_read_length / period))")
    print(f"{'load':<10}{'wf 1':>8}{'fill':>7}{'pace':>7}{'wf 2':>8}{'fill':>7}{'pace':>7}")
    for kind in ("fifo", "latest", "mixed"):
        (u1, f1, p1), (u2, f2, p2) = saturated(1, kind, s / 5), saturated(2, kind, s / 5)
        print(f"{kind:<10}{u1:>8.3f}{f1:>7.3f}{p1:>7.3f}{u2:>8.3f}{f2:>7.3f}{p2:>7.3f}  "
              f"{'ok' if u2 >= 0.9 else 'MISS'}")
    print("goal: >= 0.9 with wire format 2; use = fill x pace, pace <= 1 / 1.05 = 0.952 "
          "(the pacing margin)")
    print()
    print("Table 3: shares of a saturated link, one priority-10 topic and 49 priority-0 topics")
    print(f"{'scheduler':<26}{'top':>8}{'49 others':>11}{'least other':>13}{'starved':>9}")
    for label, strict in (("before: strict priority", True), ("after: growing claims", False)):
        r = shares(strict, s / 5)
        print(f"{label:<26}{r['top']:>8.3f}{r['others']:>11.3f}{r['min_other']:>13.4f}{r['starved']:>9}")
    print("after: expected top 11/60 = 0.183, each other 1/60 = 0.0167")
    print()
    print("Table 4: one large message in fragments over 64-byte packets (packets, bytes written)")
    print(f"{'message':<22}{'wf 1 packets':>13}{'bytes':>8}{'wf 2 packets':>14}{'bytes':>8}")
    for size, repair in ((400, 0), (2000, 0), (2000, 4)):
        (p1, b1, ok1), (p2, b2, ok2) = fragments(1, size, repair), fragments(2, size, repair)
        assert ok1 and ok2
        label = f"{size} B" + (f", {repair} repair" if repair else "")
        print(f"{label:<22}{p1:>13}{b1:>8}{p2:>14}{b2:>8}")
    print("wire format 2: compact fragment messages (H 61, 3 bytes of head, no chunk head)")


if __name__ == "__main__":
    main()
