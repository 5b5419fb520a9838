"""docs/wire-format.md sections 15.4-15.5: the worked examples are what the code computes."""
from __future__ import annotations

import re
from pathlib import Path

from uwgen.runtime.wire import envelope
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.wire.heads import Heads
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


def test_the_freshness_example_refuses_and_reports_as_written():
    text = section("### 15.5")
    assert "(age item `18 28`)" in text and "10.8 s old" in text
    wall = 1_700_000_000.0
    judge = Staleness()
    v = judge.judge(2, stamp(wall - 0.8), 10.0, 2.0, wall)
    assert v.stale and abs(v.age - 10.8) < 1 / 32 and v.offset is None
    behind = judge.judge(2, stamp(wall - 60.8), 10.0, 2.0, wall)
    assert behind.stale and behind.offset is not None and abs(behind.offset - 60.8) < 1 / 32
    assert not judge.judge(2, stamp(wall - 60.8), 0.0, 2.0, wall).stale
