"""docs/wire-format.md section 14: every worked envelope is recomputed from its row."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from uwgen.runtime.envelope import Envelope, Message, Sync, decode

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"


def rows() -> list[list[str]]:
    text = DOC.read_text().split("<!-- envelope-examples -->", 1)[1]
    table = []
    for ln in text.splitlines()[1:]:         # the table: the lines up to the first other one
        if not ln.startswith("|"):
            break
        table.append(ln)
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in table[2:]]


def hexes(s: str) -> bytes:
    return bytes.fromhex(" ".join(re.findall(r"`([0-9A-F ]*)`", s)))


def parse_parts(s: str) -> dict:
    parts: dict = {}
    if m := re.search(r"K epoch `([0-9A-F ]+)` high (\d+)", s):
        parts["sync"] = Sync(bytes.fromhex(m[1]), int(m[2]))
    if m := re.search(r"T 0x([0-9A-F]+)", s):
        parts["time"] = int(m[1], 16)
    if m := re.search(r"A `([0-9A-F ]+)`", s):
        parts["ack"] = bytes.fromhex(m[1])
    if "C empty" in s:
        parts["control"] = b""
    if "tag `00 .. 07`" in s:
        parts["tag"] = bytes(range(8))
    return parts


def test_the_doc_has_the_examples():
    assert [r[0] for r in rows()] == ["one", "three", "parts", "escape", "ack-only"]


@pytest.mark.parametrize("row", rows(), ids=lambda r: r[0])
def test_worked_envelope_is_what_the_codec_writes_and_reads(row):
    name, who, msgs, parts, wire = row
    sender, number = (int(x) for x in who.split(","))
    messages = tuple(Message(int(k), int(i), bytes.fromhex(b))
                     for k, i, b in re.findall(r"\((\d+), (\d+), `([0-9A-F ]*)`\)", msgs))
    env = Envelope(sender, number, messages, **parse_parts(parts))
    assert env.encode() == hexes(wire)
    assert decode(hexes(wire)) == env
