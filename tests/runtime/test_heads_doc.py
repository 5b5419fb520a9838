"""docs/wire-format.md section 14.3: the worked cmd_vel packet, byte by byte, recomputed from
the demo's codec, the reliability head, T, the envelope as it leaves (the age item in T) and the
short frame; and back at the receiver, the same publication time."""
from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

from uwgen.runtime.delivery.freshness import TICKS_PER_SECOND, stamp
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import encode_short_frame
from uwgen.runtime.wire.heads import Heads, decode_age, encode_age

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "wire-format.md"
DESERT = 4
BUILT = 1_700_000_000.5
AGE = 0.5


def rows() -> dict[str, tuple[str, int]]:
    section = DOC.read_text().split("### 14.3", 1)[1].split("\n## ", 1)[0]
    found = re.findall(r"^\| (unsecured|secured) \| `([0-9A-F ]+)`[^|]* \| (\d+) \|$", section, re.M)
    return {link: (data, int(air)) for link, data, air in found}


def test_section_14_3_worked_packet():
    sys.path.insert(0, str(ROOT / "generated"))
    import uwgen_demo as demo
    from uwgen_demo.geometry_msgs.msg import Twist, Vector3
    cmd = demo.TOPICS[4]
    m = envelope.from_v1(envelope.strip_packed_head(
        cmd.encode(Twist(linear=Vector3(x=0.5), angular=Vector3(z=0.3)))))
    assert (m.kind, m.id, cmd.profile, cmd.policy.ttl) == (0, 4, "packed", 2.0)
    heads = Heads(aged=frozenset({4}))
    built = envelope.Message(0, 4, encode_age(AGE) + m.body)      # as the link stamps it
    got = {}
    for link, tag in (("unsecured", None), ("secured", bytes(8))):
        e = envelope.Envelope(1, 0x10, (built,), time=stamp(BUILT))
        sent = heads.without_age(e, TICKS_PER_SECOND)
        assert sent.time == stamp(BUILT - AGE)
        frame = encode_short_frame(dataclasses.replace(sent, tag=tag).encode())
        got[link] = ((frame[:-8] if tag else frame).hex(" ").upper(), len(frame) + DESERT)
        back = heads.with_age(envelope.decode(frame[1:], 8))
        age, _ = decode_age(back.messages[0].body, 0)
        assert back.time - age * TICKS_PER_SECOND == e.time - AGE * TICKS_PER_SECOND
    assert got == rows()
    # with an A part the packet keeps T as the build time and the age item (`02`)
    acked = envelope.Envelope(1, 0x10, (built,), time=stamp(BUILT), ack=b"\x11\x51\x05")
    assert heads.without_age(acked, TICKS_PER_SECOND) == acked and built.body[0] == 0x02
