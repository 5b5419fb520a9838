"""docs/wire-format.md section 14.2: the worked cut messages and the worked sequence are what
the code computes."""
from __future__ import annotations

import re

import pytest

from uwgen.runtime.link.filling import CUT_MIN, cut_point
from uwgen.runtime.link.packets import envelope_room
from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.cuts import Joiner, cut

from .test_wire2_doc import DOC, hexes, table

SECTION = DOC.read_text()[DOC.read_text().index("### 14.2"):DOC.read_text().index("## 15.")]
ROWS = table("cut-examples")


def messages_of(cell: str) -> tuple[env.Message, ...]:
    out = []
    for head, tail, part, kind, ident, body in re.findall(
            r"(head of )?(?:(tail) `([0-9A-F ]+)`|\((\d+), (\d+), `([0-9A-F ]*)`\))", cell):
        if tail:
            out.append(env.Message(env.CUT_TAIL, 0, bytes.fromhex(part)))
            continue
        m = env.Message(int(kind), int(ident), bytes.fromhex(body))
        out.append(env.Message(env.CUT_HEAD | m.kind, m.id, m.body) if head else m)
    return tuple(out)


def test_the_section_has_its_examples():
    assert [r[0] for r in ROWS] == ["head", "tail", "tail alone", "escaped id"]


@pytest.mark.parametrize("row", ROWS, ids=[r[0] for r in ROWS])
def test_worked_cut_messages_are_what_the_codec_writes_and_reads(row):
    _name, who, msgs, wire = row
    sender, number = (int(x) for x in who.split(","))
    e = env.Envelope(sender, number, messages_of(msgs))
    assert e.encode() == hexes(wire)
    assert env.decode(hexes(wire)) == e


def test_the_head_and_tail_rows_join_to_the_message_the_text_says():
    j = Joiner()
    rows = {r[0]: env.decode(hexes(r[3])) for r in ROWS}
    assert j.feed(rows["head"]) == [env.Message(0, 4, b"ab")]
    assert j.feed(rows["tail"]) == [env.Message(0, 5, bytes(range(13))), env.Message(0, 4, b"cd")]
    assert "topic 5 with a 13-byte body" in SECTION


def test_the_worked_sequence_of_64_byte_packets():
    room = envelope_room(64)
    limit = room - 1
    assert f"L = 64 − 1 − 3 = {limit}" in SECTION
    twist = env.Message(0, 5, bytes(30))
    tail: env.Message | None = None
    heads, bodies = [], []
    for _ in range(5):
        messages = [tail] if tail else []
        messages.append(twist)
        at = cut_point(messages, twist, limit, room)
        heads.append(at)
        if at is not None:
            head, tail = cut(twist, at)
            messages.append(head)
        else:
            tail = None
        assert len(env.encode_messages(messages)) <= limit
        bodies.append(sum(len(m.body) for m in messages))
    assert heads == [26, 20, 14, 8, None]
    assert bodies == [56, 54, 54, 54, 52]
    assert "Bodies per packet: 56, 54, 54, 54, 52 of 64" in SECTION
    assert f"`first >= {CUT_MIN}`" in SECTION
