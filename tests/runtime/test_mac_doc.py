"""docs/wire-format.md section 16: every worked turn-item packet is recomputed from its row."""
from __future__ import annotations

import re

import pytest

from uwgen.runtime.link.mac import TURN_END, TURN_GRANT, MacItem, decode_items, encode_items
from uwgen.runtime.wire.envelope import Envelope, decode
from uwgen.runtime.wire.framing import encode_short_frame
from uwgen.security import control

from .test_wire2_doc import table


def items_of(text: str) -> bytes:
    out = b""
    for kind, args in re.findall(r"(grant|end|sync) ([\d ]+?)(?:,|$)", text):
        nums = [int(x) for x in args.split()]
        if kind == "sync":
            out += control.sync_request(nums[0])
        elif kind == "grant":
            out += encode_items([MacItem(TURN_GRANT, nums[0], nums[1])])
        else:
            out += encode_items([MacItem(TURN_END, nums[0])])
    return out


ROWS = table("mac-examples")


def test_the_section_has_examples():
    assert len(ROWS) == 4


@pytest.mark.parametrize("row", ROWS, ids=[r[0] for r in ROWS])
def test_worked_bytes(row):
    _what, sender, number, items, envelope, frame = row
    c = items_of(items)
    e = Envelope(int(sender), int(number, 0), (), control=c)
    hexes = lambda s: bytes.fromhex(s.strip("`"))   # noqa: E731
    assert e.encode() == hexes(envelope)
    assert encode_short_frame(e.encode()) == hexes(frame)
    back = decode(hexes(envelope))
    assert back.control == c
    assert [(i.code, i.sender) for i in decode_items(back.control)] == \
        [(i.code, i.sender) for i in decode_items(c)]
