"""docs/wire-format.md section 14.3: the worked cmd_vel packet, byte by byte, recomputed from
the demo's codec, the age item, T, the envelope and the short frame."""
from __future__ import annotations

import re
import sys
from pathlib import Path

from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import encode_short_frame
from uwgen.runtime.wire.heads import encode_age

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "wire-format.md"
DESERT = 4


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
    assert (m.kind, m.id, cmd.profile, cmd.policy.ttl) == (0, 4, "packed", 1.0)
    body = encode_age(0.0) + m.body
    got = {}
    for link, tag in (("unsecured", None), ("secured", bytes(8))):
        e = envelope.Envelope(1, 0x10, (envelope.Message(0, 4, body),), time=stamp(1_700_000_000.5), tag=tag)
        frame = encode_short_frame(e.encode())
        shown = frame[:-8] if tag else frame
        got[link] = (shown.hex(" ").upper(), len(frame) + DESERT)
    assert got == rows()
