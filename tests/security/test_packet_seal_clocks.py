"""The per-packet seal reads T with the sender's measured clock offset (docs/security.md,
"Clocks"; docs/seams.md section 8): a clock ahead is heard so its offset can be measured, and
nothing a forger or a replayer sends gets in any more than before."""
from __future__ import annotations

import logging

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.clock_offset import Offset
from uwgen.runtime.delivery.freshness import stamp
from uwgen.runtime.link.hooks import PacketHooks, join_hooks

from .helpers import WALL0, twist
from .packets import surface, vehicle


def stamped(side, wall: ManualClock) -> None:
    """`side` stamps T on every packet from `wall` (as reliability does), under the seal's."""
    side.packer.hooks = join_hooks(PacketHooks(parts=lambda now: {"time": stamp(wall.now())}),
                                   side.seal.hooks())


def pair(ahead: float, offset: Offset | None):
    """A surface whose clock is `ahead` s ahead of the vehicle's; the vehicle's seal is given
    `offset` as the surface's measured offset (reliability's, as the bridge wires it)."""
    s_wall, v_wall = ManualClock(WALL0 + ahead), ManualClock(WALL0)
    s, v = surface(wall=s_wall), vehicle(wall=v_wall)
    v.seal.use_offsets(lambda sender: offset)
    stamped(s, s_wall)
    return s, v, s_wall, v_wall


def test_a_clock_ahead_is_heard_before_its_offset_is_measured():
    # unwired (old rule) a packet 30 s from the future is stale; wired, it passes the seal
    # (reliability then refuses its commands until the offset is measured: clock_offset)
    s_wall, v_wall = ManualClock(WALL0 + 30), ManualClock(WALL0)
    s, old = surface(wall=s_wall), vehicle(wall=v_wall)
    stamped(s, s_wall)
    assert old.receive(s.send(twist(1.0))) == [] and old.stats()["stale"] == 1
    s, v, _, _ = pair(30.0, None)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    assert v.receive(s.send(twist(2.0))) == [twist(2.0)]


def test_a_clock_far_ahead_of_the_default_max_age_is_still_stale():
    s, v, _, _ = pair(200.0, None)
    assert v.receive(s.send(twist(1.0))) == [] and v.stats()["stale"] == 1


def later(s_wall: ManualClock, v_wall: ManualClock, seconds: float = 40.0) -> None:
    """Both clocks run on: a sender 30 s behind is sealed after the vehicle's start (its
    earlier packets look sealed before it: `before_start`)."""
    s_wall.advance(seconds)
    v_wall.advance(seconds)


def test_with_the_offset_measured_a_far_clock_is_read_on_ours():
    s, v, s_wall, v_wall = pair(-30.0, Offset(-30.0, 0.4, 0.8, 3))
    later(s_wall, v_wall)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    held = s.send(twist(2.0))
    v_wall.advance(130.0)                        # held 130 s: beyond the default 120 s + 5 s
    assert v.receive(held) == [] and v.stats()["stale"] == 1


def test_an_offset_with_a_large_error_is_not_trusted():
    # a held exchange gives a sample with a large error: T is then read as if unmeasured, so
    # a clock 30 s behind plus a hold of 100 s is refused as 130 s old
    s, v, s_wall, v_wall = pair(-30.0, Offset(-30.0, 40.0, 80.0, 1))
    later(s_wall, v_wall)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]          # 30 s old: within 125 s
    held = s.send(twist(2.0))
    v_wall.advance(100.0)
    assert v.receive(held) == [] and v.stats()["stale"] == 1


def test_a_replayed_or_forged_packet_is_refused_whatever_the_offset():
    for ahead, offset in ((30.0, None), (30.0, Offset(30.0, 0.3, 0.6, 2)), (0.0, None)):
        s, v, _, _ = pair(ahead, offset)
        first = s.send(twist(1.0))
        assert v.receive(first) == [twist(1.0)]
        data = s.send(twist(2.0))
        forged = bytearray(data)
        forged[-1] ^= 0x01
        assert v.receive(bytes(forged)) == [] and v.stats()["bad_tag"] == 1
        assert v.receive(data) == [twist(2.0)]
        assert v.receive(data) == [] and v.receive(first) == []     # replays
        assert v.stats()["replay"] == 2


def test_a_peer_far_behind_at_start_is_named_with_the_figure_at_its_first_packet(caplog):
    import logging
    s, v, _, _ = pair(-30.0, None)
    with caplog.at_level(logging.WARNING, logger="uwgen.security"):
        assert v.receive(s.send(twist(1.0))) == [] and v.receive(s.send(twist(2.0))) == []
    assert v.stats()["before_start"] == 2
    told = [r.getMessage() for r in caplog.records if "before_start" in r.getMessage()
            and "stamped" in r.getMessage()]
    assert len(told) == 1 and "stamped 30.0 s behind our clock" in told[0] and "GPS or NTP" in told[0]
    s, v, _, _ = pair(-2.0, None)                    # within the tolerance: a packet on its way
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="uwgen.security"):
        v.receive(s.send(twist(1.0)))
    assert not [r for r in caplog.records if "stamped" in r.getMessage()]


def test_a_clock_stepped_ahead_after_its_offset_was_measured_is_heard_again():
    # measured in step (offset 0), then the surface's clock is set 20 s ahead (GPS, NTP):
    # its packets pass the seal, so reliability can measure the new offset (never locked out)
    s, v, s_wall, v_wall = pair(0.0, Offset(0.0, 0.4, 0.8, 3))
    later(s_wall, v_wall)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    s_wall.advance(20.0)
    assert v.receive(s.send(twist(2.0))) == [twist(2.0)]
    assert v.receive(s.send(twist(3.0))) == [twist(3.0)] and v.stats()["stale"] == 0


def test_a_forged_packet_stamped_long_ago_is_counted_bad_tag_and_says_nothing_of_the_clock(caplog):
    # the clock line is said once per sender: a forgery refused for its time must not use it up
    s, v, s_wall, v_wall = pair(0.0, None)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    held = s.send(twist(2.0))
    forged = held[:-1] + bytes([held[-1] ^ 0x01])          # the tag's last byte changed
    v_wall.advance(300.0)
    with caplog.at_level(logging.ERROR, logger="uwgen.security"):
        assert v.receive(forged) == []
        assert v.stats()["bad_tag"] == 1 and v.stats()["stale"] == 0
        assert "stamped" not in caplog.text
        assert v.receive(held) == []                        # the real one, held 300 s
    assert v.stats()["stale"] == 1
    assert "a packet stamped 300.0 s behind our clock was refused" in caplog.text
