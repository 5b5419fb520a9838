"""Heads on demand (docs/wire-format.md section 14.3): T leaves a packet only when one carried
it a moment ago, and the receiver bounds a packet without T by its sender's latest earlier T,
so a held packet is still judged by its real age (however long the hold), and a packet it
cannot bound is refused, counted and left unacknowledged. The section's worked bytes."""
from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest

from uwgen.runtime.delivery import reliability as rel_mod
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.heads import encode_age

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"
WALL0 = 1_700_000_000.0
CMD = 9                       # a command: max age 30 s at the receiver


class Wall:
    def __init__(self):
        self.t = WALL0

    def now(self) -> float:
        return self.t


def receiver() -> tuple[Reliability, Wall]:
    wall = Wall()
    return Reliability(2, period=0.2, reliable={}, max_ages={CMD: 30.0}, wall=wall, name="b"), wall


def packet(number: int, built: float | None, age: float = 0.0, body: bytes = b"\xf5") -> envelope.Envelope:
    """Sender 1's packet `number` carrying one command with its age item, T when `built`."""
    m = envelope.Message(2, CMD, encode_age(age) + body)
    return envelope.Envelope(1, number, (m,), time=None if built is None else stamp(built))


def arrive(rel: Reliability, wall: Wall, e: envelope.Envelope, at: float) -> bool:
    """Whether the packet's command is taken when it arrives at wall time `at`."""
    wall.t = at
    rel.received(e, at - WALL0)
    m = e.messages[0]
    return rel.admit(envelope.to_v1(m), at - WALL0) is not None


def test_a_packet_without_t_is_judged_by_the_earlier_t_and_a_fresh_one_is_taken():
    rel, wall = receiver()
    assert arrive(rel, wall, packet(5, WALL0), WALL0 + 0.3)
    assert arrive(rel, wall, packet(6, None), WALL0 + 0.5)        # bound by packet 5's T: 0.5 s
    assert rel.counters["untimed"] == 0 and rel.counters["no_time"] == 0


@pytest.mark.parametrize("hold", [40.0, 3600.0, 2 * 86400.0])
def test_a_packet_without_t_held_for_any_time_is_refused(hold):
    rel, wall = receiver()
    assert arrive(rel, wall, packet(5, WALL0), WALL0 + 0.3)
    # packet 6 left 0.1 s after packet 5 without T and was held: judged from packet 5's T
    assert not arrive(rel, wall, packet(6, None), WALL0 + 0.1 + hold)
    assert rel.counters["stale"] + rel.counters["unexplained_delay"] == 1


def test_the_latest_earlier_t_bounds_a_late_packet_not_a_later_one():
    rel, wall = receiver()
    assert arrive(rel, wall, packet(5, WALL0), WALL0 + 0.2)
    assert arrive(rel, wall, packet(8, WALL0 + 40.0), WALL0 + 40.2)
    # packet 6 (built just after 5) arrives after packet 8: bound by 5's T, not 8's
    assert not arrive(rel, wall, packet(6, None), WALL0 + 40.3)


def test_a_packet_it_cannot_bound_is_refused_counted_and_not_acknowledged(caplog):
    rel, wall = receiver()
    with caplog.at_level(logging.WARNING, logger="uwgen.link.reliability"):
        assert not arrive(rel, wall, packet(6, None), WALL0 + 0.2)     # no T of sender 1 yet
        # more than T_REACH numbers after the only T: no bound either
        assert arrive(rel, wall, packet(10, WALL0 + 1.0), WALL0 + 1.1)
        assert not arrive(rel, wall, packet(10 + rel_mod.T_REACH + 1, None), WALL0 + 1.2)
    assert rel.counters["no_time"] == 2 and rel.counters["untimed"] == 0
    assert "counted no_time" in caplog.text
    got = next(iter(rel.engine.receipts.values()))
    assert got.largest == 10 and 6 not in got.got      # the sender counts them lost


def sender(max_age: float = 2.0) -> Reliability:
    return Reliability(1, period=0.2, reliable={}, max_ages={CMD: max_age}, wall=Wall(), name="a")


def build(rel: Reliability, number: int, now: float) -> bool:
    """Whether the sender's packet `number`, carrying a command, gets T."""
    picked = [(CMD, envelope.to_v1(envelope.Message(2, CMD, b"\x00\xf5")))]
    rel.carrying(picked, now)
    has_t = "time" in rel.parts(now)
    rel.sent(number, picked, now)
    return has_t


def test_t_goes_again_after_a_share_of_the_max_age_or_32_packets():
    rel = sender(max_age=2.0)
    got = [build(rel, n, 0.1 * n) for n in range(12)]     # T_SHARE * 2 s = 0.5 s
    assert got == [True, False, False, False, False, True, False, False, False, False, True, False]
    rel = sender(max_age=3600.0)
    got = [build(rel, n, 0.01 * n) for n in range(70)]
    assert [n for n, t in enumerate(got) if t] == [0, 33, 66]


def test_a_new_peer_gets_t_on_the_next_packet():
    rel = sender()
    assert build(rel, 0, 0.0) and not build(rel, 1, 0.1)
    rel.received(envelope.Envelope(2, 0, ()), 0.15)       # sender 2 heard for the first time
    assert build(rel, 2, 0.2)


def doc_rows() -> dict[str, tuple[str, str, str]]:
    section = DOC.read_text().split("### 14.3", 1)[1].split("\n## ", 1)[0].split("\n### ", 1)[0]
    rows = re.findall(r"^\| ([a-z-]+) \| ([^|]+) \| ([^|]+) \| `([0-9A-F ]+)` \|$", section, re.M)
    return {name: (when.strip(), what.strip(), data) for name, when, what, data in rows}


def test_section_14_3_worked_bytes():
    rows = doc_rows()
    assert set(rows) == {"timed", "untimed"}
    rel = sender()
    sent = []
    for n, now in ((0, 0.0), (1, 0.2)):
        rel.wall.t = WALL0 + 0.5 + now
        picked = [(CMD, envelope.to_v1(envelope.Message(2, CMD, b"\x00\x07\xf5")))]
        rel.carrying(picked, now)
        parts = rel.parts(now)
        rel.sent(n, picked, now)
        e = envelope.Envelope(1, 0x10 + n, (envelope.Message(2, CMD, b"\x00\x07\xf5"),),
                              time=parts.get("time"))
        sent.append(e.encode().hex(" ").upper())
    assert sent == [rows["timed"][2], rows["untimed"][2]]
