"""Seal at the moment of sending (docs/seams.md section 5): a message that waits behind newer ones is
sealed when it leaves, so its number is never older than the frames sent before it."""
from __future__ import annotations

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.scheduler import LinkScheduler

from .helpers import log_line, surface, twist, vehicle

LOW, HIGH = 7, 4


def starve(tmp_path, frames: int):
    """A low-priority log line considered (but not fitting) while a rate-held high-priority
    channel waits, then `frames` high-priority frames, then the log line; every frame goes to
    the receiver in the order it left."""
    clock = ManualClock()
    s, v = surface(tmp_path, clock=clock), vehicle(tmp_path, clock=clock)
    sched = LinkScheduler(clock, protect=s.protect, overhead=s.overhead)
    sched.add_channel(HIGH, LinkPolicy(queue="fifo", depth=frames + 1, priority=5, rate=1000.0,
                                       strict=True))   # strict: it starves LOW while it has traffic
    sched.add_channel(LOW, LinkPolicy(queue="fifo", depth=4, priority=1))
    sched.offer(HIGH, twist(0.0))
    assert sched.next_payload(0.0)[0] == HIGH              # the high channel is now rate-held
    sched.offer(LOW, log_line("low priority, long enough not to fit the room left"))
    assert sched.next_payload(0.0, max_size=20) is None    # the log line was weighed, not sent
    sent = []
    for i in range(frames):
        sched.offer(HIGH, twist(float(i)))
        picked = sched.next_payload(1.0 + i)
        assert picked is not None and picked[0] == HIGH
        sent.append(picked[1])
    sent.append(sched.next_payload(1.0 + frames)[1])
    return s, v, sent


def test_a_starved_message_sealed_when_it_leaves_is_accepted(tmp_path):
    s, v, sent = starve(tmp_path, 200)                     # more than the 128-frame window
    delivered = [v.unprotect(frame) for frame in sent]
    assert all(p is not None for p in delivered), v.stats()
    assert delivered[-1] == log_line("low priority, long enough not to fit the room left")
    assert v.stats()["too_old"] == 0 and v.stats()["verified"] == 201


def test_frames_leave_in_the_order_of_their_numbers(tmp_path):
    s, v, sent = starve(tmp_path, 10)
    import uwgen.security.wire as wire
    partials = [wire.parse(f).partial for f in sent]
    assert partials == sorted(partials)
