"""docs/wire-format.md section 14: every worked envelope is recomputed from its row."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from uwgen.runtime.wire.envelope import FRAGMENT, Envelope, Message, Sync, decode, from_v1

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"


def table(marker: str) -> list[list[str]]:
    """The rows of the table right after `<!-- marker -->` (header and rule skipped)."""
    lines = DOC.read_text().split(f"<!-- {marker} -->", 1)[1].strip().splitlines()
    block = []
    for ln in lines:
        if not ln.startswith("|"):
            break
        block.append(ln)
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in block[2:]]


def rows() -> list[list[str]]:
    return table("envelope-examples")


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
    assert [r[0] for r in rows()] == ["one", "three", "parts", "escape", "ack-only", "run",
                                      "run, then one"]


@pytest.mark.parametrize("row", rows(), ids=lambda r: r[0])
def test_worked_envelope_is_what_the_codec_writes_and_reads(row):
    name, who, msgs, parts, wire = row
    sender, number = (int(x) for x in who.split(","))
    messages = tuple(Message(int(k), int(i), bytes.fromhex(b))
                     for k, i, b in re.findall(r"\((\d+), (\d+), `([0-9A-F ]*)`\)", msgs))
    env = Envelope(sender, number, messages, **parse_parts(parts))
    assert env.encode() == hexes(wire)
    assert decode(hexes(wire)) == env


def fragment_rows() -> list[list[str]]:
    return table("fragment-examples")


def test_the_doc_has_the_fragment_examples():
    assert [r[0] for r in fragment_rows()] == ["data", "repair"]


@pytest.mark.parametrize("row", fragment_rows(), ids=lambda r: r[0])
def test_worked_fragment_message_is_what_the_codec_writes_and_reads(row):
    from uwgen.runtime.wire.fragment import Fragment, encode_compact, parse_compact
    _name, head, chunk, size, message = row
    transfer, index, count = (int(x) for x in head.split(","))
    f = Fragment(transfer, index, count, hexes(chunk), int(size) if size else None)
    assert encode_compact(f) == hexes(message)
    assert parse_compact(hexes(message)) == f
    # as a message of an envelope: kind FRAGMENT, no id, the body after H
    env = Envelope(1, 1, (Message(0, 4, b"\x01"), from_v1(hexes(message))))
    assert decode(env.encode()).messages[1] == Message(FRAGMENT, 0, hexes(message)[1:])


def test_the_repair_example_inside_an_envelope_reads_as_the_doc_says():
    from uwgen.runtime.wire.fragment import Fragment, encode_compact
    frag = from_v1(encode_compact(Fragment(200, 3, 3, bytes.fromhex("AABB"), 5)))
    env = Envelope(0, 0, (frag, Message(0, 4, b"\x01")))
    assert env.encode()[3:12] == bytes.fromhex("E1 07 C8 03 03 00 05 AA BB")
