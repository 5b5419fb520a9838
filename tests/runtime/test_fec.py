"""Repair fragments: any k of the k + r fragments rebuild a message (wire format section 11).

The erasure code comes from zfec; `Reference` below recomputes it from the formula written in
the wire format with plain Python, so the spec, not the library, is what the tests hold to.
"""
from __future__ import annotations

import random
from functools import reduce

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.linksim import LinkSim
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.wire import fec
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.fragment import (
    Fragment, FragmentError, Fragmenter, encode_fragment, fragment_payload_for, parse_fragment)
from uwgen.runtime.wire.reassembly import Reassembler

FID = 250


class Reference:
    """GF(2^8) mod x^8+x^4+x^3+x^2+1; G = V * inverse(V[:k]), V row 0 = e0, row i = alpha^((i-1)j)."""

    EXP: list[int] = []
    LOG = [0] * 256
    x = 1
    for i in range(255):
        EXP.append(x)
        LOG[x] = i
        x = (x << 1) ^ (0x11D if x & 0x80 else 0)
    EXP += EXP

    @classmethod
    def mul(cls, a: int, b: int) -> int:
        return 0 if a == 0 or b == 0 else cls.EXP[cls.LOG[a] + cls.LOG[b]]

    @classmethod
    def inverse(cls, m: list[list[int]]) -> list[list[int]]:
        n = len(m)
        a = [row[:] + [int(i == j) for j in range(n)] for i, row in enumerate(m)]
        for c in range(n):
            p = next(r for r in range(c, n) if a[r][c])
            a[c], a[p] = a[p], a[c]
            f = cls.EXP[255 - cls.LOG[a[c][c]]]
            a[c] = [cls.mul(f, v) for v in a[c]]
            for r in range(n):
                if r != c and a[r][c]:
                    g = a[r][c]
                    a[r] = [v ^ cls.mul(g, w) for v, w in zip(a[r], a[c])]
        return [row[n:] for row in a]

    @classmethod
    def generator(cls, k: int, n: int) -> list[list[int]]:
        v = [[1] + [0] * (k - 1)] + [[cls.EXP[(i - 1) * j % 255] for j in range(k)] for i in range(1, n)]
        top = cls.inverse(v[:k])
        return [[reduce(lambda acc, t: acc ^ cls.mul(v[i][t], top[t][j]), range(k), 0) for j in range(k)]
                for i in range(n)]

    @classmethod
    def repair(cls, data: list[bytes], r: int) -> list[bytes]:
        k, size = len(data), len(data[0])
        g = cls.generator(k, k + r)
        return [bytes(reduce(lambda acc, j: acc ^ cls.mul(g[i][j], data[j][b]), range(k), 0) for b in range(size))
                for i in range(k, k + r)]


def test_the_generator_is_systematic():
    g = Reference.generator(4, 6)
    assert g[:4] == [[int(i == j) for j in range(4)] for i in range(4)]


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 10), st.integers(1, 5), st.integers(1, 12), st.randoms(use_true_random=False))
def test_repair_blocks_follow_the_formula_of_the_wire_format(k, r, size, rnd):
    data = [rnd.randbytes(size) for _ in range(k)]
    assert fec.repair_blocks(data, r) == Reference.repair(data, r)


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 30), st.integers(0, 10), st.integers(1, 40), st.randoms(use_true_random=False))
def test_any_k_of_k_plus_r_blocks_rebuild_the_data(k, r, size, rnd):
    data = [rnd.randbytes(size) for _ in range(k)]
    blocks = dict(enumerate(data + fec.repair_blocks(data, r)))
    kept = rnd.sample(sorted(blocks), k)
    assert fec.rebuild(k, r, {n: blocks[n] for n in kept}) == data


def test_fewer_than_k_blocks_cannot_rebuild():
    data = [b"ab", b"cd", b"ef"]
    blocks = dict(enumerate(data + fec.repair_blocks(data, 2)))
    with pytest.raises(ValueError, match="need 3 blocks"):
        fec.rebuild(3, 2, {0: blocks[0], 4: blocks[4]})


@settings(max_examples=200, deadline=None)
@given(st.integers(24, 255), st.integers(1, 4000), st.integers(1, 8), st.randoms(use_true_random=False))
def test_any_k_of_the_k_plus_r_fragments_rebuild_the_message_in_any_order(room, size, r, rnd):
    fr = Fragmenter(FID, rng=rnd, max_payload=room)
    payload = rnd.randbytes(min(size, fr.max_message_for(r)))
    parts = fr.split(payload, r)
    assert all(len(p) <= room for p in parts)
    k = parse_fragment(parts[0], FID).count
    assert len(parts) == k + r
    kept = rnd.sample(parts, k)
    reasm = Reassembler(FID, ManualClock())
    out = [m for p in kept if (m := reasm.feed(p)) is not None]
    assert out == [payload]
    assert reasm.pending == 0


def fragments(payload: bytes, r: int = 2, room: int = 60):
    return Fragmenter(FID, rng=random.Random(1), max_payload=room).split(payload, r)


def test_repairs_after_a_whole_message_are_surplus_not_a_new_partial():
    parts = fragments(bytes(range(200)))
    reasm = Reassembler(FID, ManualClock())
    got = [reasm.feed(p) for p in parts]
    k = len(parts) - 2
    assert got[k - 1] == bytes(range(200)) and got.count(None) == len(parts) - 1
    assert reasm.pending == 0
    assert reasm.stats["surplus_repair"] == 2 and reasm.stats["rebuilt"] == 0


def test_a_message_rebuilt_from_repairs_is_counted_rebuilt():
    parts = fragments(bytes(range(200)))
    reasm = Reassembler(FID, ManualClock())
    got = [reasm.feed(p) for i, p in enumerate(parts) if i not in (0, 2)]
    assert got[-1] == bytes(range(200))
    assert reasm.stats["rebuilt"] == 1 and reasm.stats["completed"] == 1


def test_a_repair_disagreeing_on_the_message_size_drops_the_partial():
    parts = fragments(bytes(range(200)))
    f = parse_fragment(parts[-1], FID)
    forged = encode_fragment(FID, Fragment(f.transfer, f.index, f.count, f.chunk, f.size - 1))
    reasm = Reassembler(FID, ManualClock())
    reasm.feed(parts[-2])
    reasm.feed(forged)
    assert reasm.stats["inconsistent"] == 1


@pytest.mark.parametrize("hexbytes, message", [
    ("00 18 FA 00 03 03 41 00", "no size item"),
    ("00 18 FA 00 03 02 41 00 05", "size 5 cannot be 2 chunks of at most 1"),
    ("00 18 FA 00 03 02 41 00 02 00", "1 bytes after the size"),
])
def test_malformed_repair_fragments_are_refused_with_a_reason(hexbytes, message):
    with pytest.raises(FragmentError, match=message):
        parse_fragment(bytes.fromhex(hexbytes), FID)


# The worked example of wire format section 11: a std_msgs/String on id 7, fragment_id 250,
# max_read_length 32 (fragment payloads of at most 28 bytes), transfer 42, repair 2.
WORKED_PAYLOAD = bytes.fromhex("00 07 78 24") + b"depth 12.5 m, battery 87 %, all well"
WORKED = [
    "00 18 FA 18 2A 00 03 50 00 07 78 24 64 65 70 74 68 20 31 32 2E 35 20 6D",
    "00 18 FA 18 2A 01 03 50 2C 20 62 61 74 74 65 72 79 20 38 37 20 25 2C 20",
    "00 18 FA 18 2A 02 03 48 61 6C 6C 20 77 65 6C 6C",
    "00 18 FA 18 2A 03 03 50 26 45 D0 2E 8E ED 90 14 8D E0 DF B6 BA 0B 80 4C 18 28",
    "00 18 FA 18 2A 04 03 50 FB E9 0F 38 BA 72 EA E9 6B 87 FA 80 1C 04 DA E4 18 28",
]


def test_worked_bytes_of_section_11():
    fr = Fragmenter(FID, rng=random.Random(0), max_payload=fragment_payload_for(32))
    fr._next_transfer = 42
    assert [p.hex(" ").upper() for p in fr.split(WORKED_PAYLOAD, 2)] == WORKED
    data = [bytes.fromhex(h)[8:] for h in WORKED[:3]]
    data[2] = data[2].ljust(16, b"\0")
    assert [bytes.fromhex(h)[8:24] for h in WORKED[3:]] == Reference.repair(data, 2)
    # Fragments 1 and 2 lost: 0, 3 and 4 rebuild the message.
    reasm = Reassembler(FID, ManualClock())
    out = [reasm.feed(bytes.fromhex(WORKED[i])) for i in (0, 3, 4)]
    assert out[-1] == WORKED_PAYLOAD


def lossy_run(repair: int, per: float = 0.2, messages: int = 300, seed: int = 7) -> float:
    scenario = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                               NodeSpec("b", position=(300, 0, 0), dest="a")],
                        period=0.2, max_read_length=64, per=per, seed=seed, bitrate=4800.0)
    sim = LinkSim(scenario, "a", "b", fragment_id=FID, rng=random.Random(seed))
    sim.sender.add_channel(7, LinkPolicy(queue="fifo", depth=messages, repair=repair))
    size = 180                  # four fragments of at most 48 (with repair) or 51 bytes
    spacing = (4 + repair) * 0.2 * 1.1
    for i in range(messages):
        sim.at(i * spacing, lambda i=i: sim.sender.offer(7, i.to_bytes(4, "big") + bytes(size - 4)))
    sim.run(messages * spacing + 5)
    # 4 data fragments (a payload longer than a packet never travels as one frame) + `repair`.
    assert sim.sender.scheduler.stats()[7]["fragments_sent"] == messages * (4 + repair)
    return len(sim.received) / messages


def test_a_four_fragment_message_survives_20_percent_packet_loss_with_two_repairs():
    # Exactly: P(at least 4 of 6 arrive) = 0.901 at PER 0.2; without repair all four fragments
    # must arrive: 0.8^4 = 0.41.
    with_repair = lossy_run(repair=2)
    without = lossy_run(repair=0)
    assert with_repair > 0.86
    assert without < 0.6
