"""When a command that came began on its sender's side (uwgen.runtime.delivery.judge.AgeJudge
.taken; docs/wire-format.md section 15.6, "A command's copy in its own turn"): from the age
item of the copy that came and the packet's transit, the offset taken off, so the serving
side times its caller's deadline on the call, not on the arrival of its first copy that got
through. Explicit clocks."""
from __future__ import annotations

import pytest

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.clock_offset import Offset
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.delivery.judge import BEGUN, AgeJudge
from uwgen.runtime.delivery.staleness import Staleness
from uwgen.runtime.stats import Counters
from uwgen.runtime.delivery.reliability import COUNTERS
from uwgen.runtime.wire.heads import AGE_UNIT

CALL = 20
WALL = 1_700_000_000.0


def judge(offset: float | None = None) -> tuple[AgeJudge, ManualClock]:
    wall = ManualClock(WALL)
    j = AgeJudge(0, "vehicle", wall, Counters(COUNTERS), {CALL: 12.0})
    if offset is not None:
        j.offsets.of = lambda peer: Offset(offset, 0.3, 0.6, 4)
    return j, wall


def test_the_likely_age_is_the_age_item_and_the_transit_without_the_offsets_error():
    verdict = Staleness().judge(stamp(WALL - 1.5), 7.0, 12.0, WALL, Offset(-0.5, 0.4, 0.8, 3))
    assert verdict.refused is None
    # transit 1.5 s on our clock less the sender's 0.5 s behind: 1.0 s (to the stamp's 1/32)
    assert verdict.likely == pytest.approx(7.0 + AGE_UNIT / 2 + 1.0, abs=1 / 32)
    assert verdict.age > verdict.likely                       # the bound counts the error


def test_a_command_taken_began_its_age_item_and_transit_before_it_came():
    j, wall = judge(offset=0.0)
    request = bytes((2, CALL, 7, 1))
    assert not j.refuses(CALL, 1, stamp(WALL - 1.4), 7.5)     # a copy: the call 7.5 s old
    j.taken(request, 500.0)                                   # on the link's clock
    assert j.began(request) == pytest.approx(500.0 - 7.5 - AGE_UNIT / 2 - 1.4, abs=1 / 32)
    assert j.began(bytes((2, CALL, 8, 1))) is None            # never taken


def test_a_command_refused_tells_nothing_and_only_the_last_taken_are_kept():
    j, wall = judge(offset=0.0)
    late = bytes((2, CALL, 9, 1))
    assert j.refuses(CALL, 1, stamp(WALL - 1.4), 11.5)        # past its 12 s: refused
    j.taken(late, 500.0)
    assert j.began(late) is None
    for seq in range(BEGUN + 1):
        assert not j.refuses(CALL, 1, stamp(WALL - 1.0), 1.0)
        j.taken(bytes((2, CALL, seq % 256, 2)), 500.0)
    assert j.began(bytes((2, CALL, 0, 2))) is None            # the oldest forgotten
    assert j.began(bytes((2, CALL, BEGUN, 2))) is not None
