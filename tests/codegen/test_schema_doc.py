"""The worked examples of wire-format.md section 10 are what the code computes."""
from __future__ import annotations

import re
from pathlib import Path

import cbor2

from uwgen.bridge.schema import decode_announcement, encode_announcements
from uwgen.codegen.fingerprint import description, digest
from uwgen.codegen.ir import IRBuilder
from uwgen.idl.loader import InterfaceLibrary

DOC = (Path(__file__).resolve().parents[2] / "docs" / "wire-format.md").read_text()
SECTION = DOC[DOC.index("## 10. Schema fingerprints"):]


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def test_worked_fingerprint_of_a_bool_topic():
    found = re.search(r"hashes a\s+(\d+)-byte description to the fingerprint `([0-9A-F ]+)`", SECTION)
    assert found, "section 10.1 lost its worked example"
    lib = InterfaceLibrary([], installed=True)
    ct = IRBuilder(lib.get).codec(lib.get("std_msgs/msg/Bool"), "native")
    desc = description("topic", [0], 7, "native", "std_msgs/msg/Bool", [ct], {ct.key: ct})
    assert len(cbor2.dumps(desc, canonical=True)) == int(found.group(1))
    assert digest(desc) == hexbytes(found.group(2))


def test_worked_announcement_bytes():
    block = re.search(r"```\n([0-9A-F ]+)\n```", SECTION).group(1)
    fp7 = hexbytes(re.search(r"fingerprint `([0-9A-F ]+)`", SECTION).group(1))
    payloads = encode_announcements(249, [(20, hexbytes("A4 95 96 A3")), (7, fp7)], request=True)
    assert payloads == [hexbytes(block)]
    ann = decode_announcement(hexbytes(block), 249)
    assert ann.request and ann.pairs == ((7, fp7), (20, hexbytes("A4 95 96 A3")))
    assert len(hexbytes(block)) + 4 == 20      # 2 ids: a 16-byte payload, a 20-byte frame


def test_stated_announcement_size_for_three_ids():
    payloads = encode_announcements(249, [(3, b"abcd"), (4, b"efgh"), (20, b"ijkl")], request=False)
    assert "a manifest of 3 ids is announced in a 26-byte frame" in SECTION
    assert [len(p) + 4 for p in payloads] == [26]
