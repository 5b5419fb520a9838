"""docs/wire-format.md sections 15.4-15.5: the worked examples are what the code computes."""
from __future__ import annotations

import re
from pathlib import Path

from uwgen.runtime.wire import envelope
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.wire.heads import Heads
from uwgen.runtime.delivery.clock_offset import ClockOffsets, Offset
from uwgen.runtime.delivery.staleness import Staleness

DOC = (Path(__file__).resolve().parents[2] / "docs" / "wire-format.md").read_text()


def section(title: str) -> str:
    start = DOC.index(title)
    return DOC[start:DOC.index("\n### ", start + 1)]


def hexbytes(cell: str) -> bytes:
    return bytes.fromhex(cell.strip().strip("`"))


def test_every_row_of_the_head_examples_is_what_the_sender_writes_and_the_receiver_reads():
    text = section("### 15.4")
    table = text[text.index("<!-- head-examples -->"):]
    rows = [r for r in table.splitlines()[3:] if r.startswith("|")]
    assert len(rows) == 3
    for row in rows:
        _, example, entry, n, age, payload, body, _ = [c.strip() for c in row.split("|")]
        ident = int(re.search(r"id (\d+)", entry).group(1))
        heads = Heads(numbered=frozenset({ident} if "reliable" in entry else ()),
                      aged=frozenset({ident}))
        if n:
            heads._next[ident] = int(n, 16)
        seconds = float(re.match(r"([\d.]+) s", age).group(1))
        stamped, number = heads.add(hexbytes(payload), seconds)
        assert envelope.from_v1(stamped).body == hexbytes(body), example
        back = heads.take(stamped)
        assert back.payload == hexbytes(payload) and back.number == (int(n, 16) if n else None)
        assert back.age == int(re.search(r"(\d+) units", age).group(1)) * 0.25


def test_the_worked_packet_carries_t_a_and_the_reliable_message():
    text = section("### 15.4")
    quoted = re.search(r"carrying the reliable topic row: `([0-9A-F ]+)\s*\n?\s*([0-9A-F ]+)`", text)
    written = bytes.fromhex(quoted.group(1) + " " + quoted.group(2))
    t = stamp(1_700_000_000.5)
    assert f"T = 0x{t:06X}" in text
    env = envelope.Envelope(2, 0x10, (envelope.Message(0, 7, bytes.fromhex("2A 05 F5")),),
                            time=t, ack=bytes.fromhex("11 51 05 7F"))
    assert env.encode() == written


def test_the_freshness_example_refuses_as_written():
    text = section("### 15.5")
    assert "(age item `18 28`)" in text and "11.05 s old" in text and "16.05 s old" in text
    wall = 1_700_000_000.0
    judge = Staleness()
    measured = Offset(0.0, 0.0, 0.0, 1)
    v = judge.judge(stamp(wall - 0.8), 10.0, 2.0, wall, measured)
    assert v.refused == "stale" and abs(v.age - 11.05) < 1 / 32
    before = judge.judge(stamp(wall - 0.8), 10.0, 2.0, wall)
    assert before.refused == "stale" and abs(before.age - 16.05) < 1 / 32


def test_the_clock_offset_example_is_what_the_exchange_computes():
    text = section("### 15.5")
    t1, t4 = 1_700_000_000.0, 1_700_000_003.1
    t = int(re.search(r"T = `([0-9A-F ]+)`", text).group(1).replace(" ", ""), 16)
    assert t == stamp(1_699_999_999.2) and "(1 699 999 999.1875)" in text
    offsets = ClockOffsets()
    offsets.built(0x123, t1)
    got = offsets.reported(2, 0x123, 5, t, t4)
    figures = re.search(r"Offset = (-?[\d.]+) s,\s+delay ([\d.]+) s, error ([\d.]+) s", text)
    assert (round(got.offset, 2), round(got.delay, 3), round(got.error, 2)) == \
        tuple(float(x) for x in figures.groups())
    judge, sent = Staleness(), stamp(1_700_000_000.0)
    taken = judge.judge(sent, 0.5, 5.0, 1_700_000_004.0, got)
    assert taken.refused is None and round(taken.transit, 2) == 0.95 and round(taken.age, 2) == 2.75
    held = judge.judge(sent, 0.5, 5.0, 1_700_000_048.0, got)
    assert held.refused == "stale" and round(held.age, 2) == 46.75
    assert judge.judge(sent, 0.5, 5.0, 1_700_000_048.0).refused == "unexplained_delay"
    assert "1 700 000 048.0: at most 46.75 s old, refused `stale`" in text and "refused `unexplained_delay`" in text
