"""Link scheduler: queue disciplines, rate, ttl, priority, fragments and the accounting invariant."""
from __future__ import annotations

import logging
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.fragment import Fragmenter
from uwgen.runtime.wire.reassembly import Reassembler
from uwgen.runtime.link.scheduler import DROP_REASONS, LinkScheduler

FID = 250


def msg(key: int, n: int, size: int = 8) -> bytes:
    """A recognisable payload: kind 0, channel key, a 4-byte serial, padding."""
    return bytes((0, key)) + n.to_bytes(4, "big") + bytes(max(0, size - 6))


def serial(payload: bytes) -> int:
    return int.from_bytes(payload[2:6], "big")


def drain(s: LinkScheduler, now: float) -> list[tuple[int, bytes]]:
    out = []
    while (p := s.next_payload(now)) is not None:
        out.append(p)
    return out


def accounted(stats: dict) -> int:
    return stats["sent"] + sum(stats[r] for r in DROP_REASONS) + stats["queued"]


# -- queue disciplines ---------------------------------------------------------------------------

def test_latest_keeps_only_the_newest_and_counts_superseded():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="latest"))
    for n in range(5):
        assert s.offer(4, msg(4, n))
    assert drain(s, 0) == [(4, msg(4, 4))]
    st_ = s.stats()[4]
    assert st_["superseded"] == 4 and st_["sent"] == 1 and accounted(st_) == st_["offered"] == 5


def test_fifo_keeps_depth_in_order_and_drops_the_oldest_on_overflow():
    s = LinkScheduler(ManualClock())
    s.add_channel(7, LinkPolicy(queue="fifo", depth=3))
    for n in range(5):
        s.offer(7, msg(7, n))
    assert [serial(p) for _, p in drain(s, 0)] == [2, 3, 4]
    assert s.stats()[7]["overflow"] == 2


def test_fifo_sends_everything_that_fits():
    s = LinkScheduler(ManualClock())
    s.add_channel(7, LinkPolicy(queue="fifo", depth=8))
    for n in range(8):
        s.offer(7, msg(7, n))
    assert [serial(p) for _, p in drain(s, 0)] == list(range(8))
    assert s.stats()[7]["overflow"] == 0


# -- rate ----------------------------------------------------------------------------------------

def test_rate_limits_messages_per_second():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(4, LinkPolicy(queue="fifo", depth=100, rate=5))
    for n in range(20):
        s.offer(4, msg(4, n))
    sent_at = []
    for step in range(101):                      # one second in 10 ms steps
        t = step * 0.01
        clock.set(t)
        sent_at += [t for _ in drain(s, t)]
    assert len(sent_at) == 6                      # t = 0, 0.2, ..., 1.0
    assert all(b - a >= 0.2 - 1e-9 for a, b in zip(sent_at, sent_at[1:]))


def test_rate_limited_counts_each_held_message_once():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10, rate=1))
    s.offer(4, msg(4, 0))
    s.offer(4, msg(4, 1))
    assert s.next_payload(0.0) is not None
    for t in (0.1, 0.2, 0.3):
        assert s.next_payload(t) is None
    assert s.stats()[4]["rate_limited"] == 1
    assert s.next_payload(1.0) == (4, msg(4, 1))


def test_next_ready_time_reports_when_the_rate_allows():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10, rate=2))
    assert s.next_ready_time(0) is None
    s.offer(4, msg(4, 0))
    s.offer(4, msg(4, 1))
    assert s.next_ready_time(0) == 0
    s.next_payload(0)
    assert s.next_ready_time(0.1) == pytest.approx(0.5)


def test_a_link_writing_once_a_frame_lets_a_rate_limited_channel_spend_the_frames_worth():
    # TDMA: the link writes only in its slot, once a 3.7 s frame; a 1/s channel may send
    # 3.7 a frame on average, so its slot's writes (0.21 s apart) carry them, not one
    s = LinkScheduler(ManualClock(), burst=3.7)
    s.add_channel(4, LinkPolicy(queue="fifo", depth=100, rate=1))
    for n in range(20):
        s.offer(4, msg(4, n))
    sent = [t for t in (10.0, 10.21, 10.42, 10.63, 10.84) if s.next_payload(t) is not None]
    assert sent == [10.0, 10.21, 10.42, 10.63]          # 3.7 tokens, then 0.33 + 0.84 s of refill
    assert s.next_ready_time(10.84) == pytest.approx(10.63 + 0.67 + 0.0, abs=0.01)
    plain = LinkScheduler(ManualClock())                  # no burst: one per second, as before
    plain.add_channel(4, LinkPolicy(queue="fifo", depth=100, rate=1))
    plain.offer(4, msg(4, 0))
    plain.offer(4, msg(4, 1))
    assert [plain.next_payload(t) is not None for t in (10.0, 10.21)] == [True, False]


# -- ttl -----------------------------------------------------------------------------------------

def test_message_older_than_ttl_is_dropped_never_sent():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10, ttl=1.0))
    s.offer(4, msg(4, 0))
    clock.advance(0.5)
    s.offer(4, msg(4, 1))
    assert [serial(p) for _, p in drain(s, 1.2)] == [1]
    assert s.stats()[4]["expired"] == 1


def test_ttl_runs_from_publication_not_from_the_offer():
    clock = ManualClock(10.0)
    s = LinkScheduler(clock)
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10, ttl=1.0))
    s.offer(4, msg(4, 0), published=8.5)        # published 1.5 s before the bridge took it
    s.offer(4, msg(4, 1), published=9.5)
    s.offer(4, msg(4, 2), published=11.0)      # a stamp ahead of the clock counts as now
    assert [serial(p) for _, p in drain(s, 10.8)] == [2]
    assert s.stats()[4]["expired"] == 2


def test_message_exactly_ttl_old_is_still_sent():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(4, LinkPolicy(ttl=1.0))
    s.offer(4, msg(4, 0))
    assert s.next_payload(1.0) == (4, msg(4, 0))


# -- priority ------------------------------------------------------------------------------------

def test_highest_priority_ready_channel_goes_first():
    s = LinkScheduler(ManualClock())
    s.add_channel(6, LinkPolicy(priority=1))
    s.add_channel(4, LinkPolicy(priority=10))
    s.add_channel(5, LinkPolicy(priority=5))
    for k in (6, 4, 5):
        s.offer(k, msg(k, 0))
    assert [k for k, _ in drain(s, 0)] == [4, 5, 6]


def test_equal_priorities_take_turns():
    s = LinkScheduler(ManualClock())
    for k in (3, 1, 2):
        s.add_channel(k, LinkPolicy(queue="fifo", depth=10, priority=5))
        for n in range(3):
            s.offer(k, msg(k, n))
    assert [k for k, _ in drain(s, 0)] == [1, 2, 3, 1, 2, 3, 1, 2, 3]


def test_rate_limited_high_priority_lets_lower_priority_through():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10, rate=1, priority=10))
    s.add_channel(7, LinkPolicy(queue="fifo", depth=10, priority=0))
    for n in range(2):
        s.offer(4, msg(4, n))
        s.offer(7, msg(7, n))
    assert [k for k, _ in drain(s, 0)] == [4, 7, 7]


# -- refusals ------------------------------------------------------------------------------------

def test_payload_over_255_without_fragmenter_is_refused_with_logged_error(caplog):
    s = LinkScheduler(ManualClock(), name="vehicle")
    s.add_channel(7, LinkPolicy(), name="/vehicle/log")
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        assert not s.offer(7, msg(7, 0, size=256))
    assert s.stats()[7]["too_large"] == 1 and s.stats()[7]["queued"] == 0
    assert "/vehicle/log" in caplog.text and "256-byte" in caplog.text and "fragment_id" in caplog.text
    assert s.offer(7, msg(7, 1, size=255))


def test_repeated_refusals_are_logged_once_then_sparingly(caplog):
    s = LinkScheduler(ManualClock())
    s.add_channel(7, LinkPolicy())
    with caplog.at_level(logging.ERROR, logger="uwgen.link"):
        for n in range(50):
            s.offer(7, msg(7, n, size=300))
    assert len(caplog.records) == 2          # the first, and the 10th
    assert s.stats()[7]["too_large"] == 50


def test_empty_payload_is_refused_and_counted_invalid():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy())
    assert not s.offer(4, b"")
    assert s.stats()[4]["invalid"] == 1


def test_unknown_channel_is_a_clear_error():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy())
    with pytest.raises(KeyError, match="no channel 9"):
        s.offer(9, msg(9, 0))


def test_channel_added_twice_is_an_error():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy())
    with pytest.raises(ValueError, match="already"):
        s.add_channel(4, LinkPolicy())


def test_unknown_queue_kind_is_an_error():
    s = LinkScheduler(ManualClock())
    with pytest.raises(ValueError, match="unknown queue kind 'lifo'"):
        s.add_channel(4, LinkPolicy(queue="lifo"))


# -- fragments -----------------------------------------------------------------------------------

def fragmenting_scheduler(clock=None) -> LinkScheduler:
    fr = Fragmenter(FID, rng=random.Random(1))
    return LinkScheduler(clock or ManualClock(), splitter=fr.split, max_message=fr.max_message_size)


def test_large_payload_leaves_as_fragments_and_counts_as_sent_once_complete():
    s = fragmenting_scheduler()
    s.add_channel(7, LinkPolicy())
    s.offer(7, msg(7, 0, size=600))
    first = s.next_payload(0)
    assert first is not None and len(first[1]) <= 255
    assert s.stats()[7]["sent"] == 0 and s.stats()[7]["queued"] == 1
    rest = drain(s, 0)
    assert len(rest) == 2 and s.stats()[7]["sent"] == 1 and s.stats()[7]["fragments_sent"] == 3
    r = Reassembler(FID, ManualClock())
    assert [m for _, p in [first, *rest] if (m := r.feed(p)) is not None] == [msg(7, 0, size=600)]


def test_higher_priority_gets_in_between_fragments():
    s = fragmenting_scheduler()
    s.add_channel(7, LinkPolicy(priority=0))
    s.add_channel(4, LinkPolicy(priority=10))
    s.offer(7, msg(7, 0, size=700))
    assert s.next_payload(0)[0] == 7
    s.offer(4, msg(4, 0))
    assert s.next_payload(0) == (4, msg(4, 0))
    assert [k for k, _ in drain(s, 0)] == [7, 7]


def test_message_in_fragments_is_finished_not_superseded_or_expired():
    clock = ManualClock()
    s = fragmenting_scheduler(clock)
    s.add_channel(7, LinkPolicy(queue="latest", ttl=1.0))
    s.offer(7, msg(7, 0, size=600))
    s.next_payload(0)
    s.offer(7, msg(7, 1, size=600))           # waits behind the transfer in progress
    s.offer(7, msg(7, 2, size=600))           # supersedes the waiting one only
    clock.set(5.0)
    out = drain(s, 5.0)
    assert len(out) == 2                      # the rest of message 0; message 2 expired
    st_ = s.stats()[7]
    assert (st_["sent"], st_["superseded"], st_["expired"], st_["queued"]) == (1, 1, 1, 0)


def test_payload_too_large_even_for_fragments_is_refused():
    fr = Fragmenter(FID, max_fragments=3)
    s = LinkScheduler(ManualClock(), splitter=fr.split, max_message=fr.max_message_size)
    s.add_channel(7, LinkPolicy())
    assert s.offer(7, msg(7, 0, size=fr.max_message_size))
    assert not s.offer(7, msg(7, 1, size=fr.max_message_size + 1))
    assert s.stats()[7]["too_large"] == 1


# -- the invariant, under random traffic ------------------------------------------------------------

POLICY = st.builds(
    LinkPolicy,
    rate=st.one_of(st.none(), st.sampled_from([0.5, 1, 2, 5, 10])),
    queue=st.sampled_from(["latest", "fifo"]),
    depth=st.integers(1, 5),
    ttl=st.one_of(st.none(), st.sampled_from([0.1, 0.5, 1.0, 3.0])),
    priority=st.integers(0, 3),
).map(lambda p: p if p.queue == "fifo" else LinkPolicy(p.rate, "latest", 1, p.ttl, p.priority))

OP = st.one_of(
    st.tuples(st.just("offer"), st.integers(0, 3), st.sampled_from([0, 8, 40, 255, 256, 700, 5000])),
    st.tuples(st.just("tick"), st.sampled_from([0.0, 0.01, 0.05, 0.2, 0.7])),
    st.tuples(st.just("send"), st.integers(1, 3)),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(POLICY, min_size=1, max_size=4), st.lists(OP, max_size=120), st.booleans())
def test_every_offered_message_is_accounted_for_exactly_once(policies, ops, fragments):
    """offered == sent + superseded + overflow + expired + too_large + invalid + queued, always;
    and what is sent obeys the policies: never twice, in order, never older than ttl when it
    starts, starts no closer than 1/rate apart, and a `latest` channel starts only its newest."""
    clock = ManualClock()
    if fragments:
        fr = Fragmenter(FID, rng=random.Random(0), max_fragments=8)
        s = LinkScheduler(clock, splitter=fr.split, max_message=fr.max_message_size)
    else:
        s = LinkScheduler(clock)
    for key, pol in enumerate(policies):
        s.add_channel(key, pol)
    r = Reassembler(FID, clock)
    offered_at: dict[tuple[int, int], float] = {}
    newest: dict[int, int] = {}
    started: dict[int, tuple[float, int]] = {}     # channel -> start of the message in fragments
    sent: list[tuple[int, int, float, int]] = []   # key, serial, start time, newest at start
    n = 0
    for op in ops:
        if op[0] == "offer":
            key = op[1] % len(policies)
            n += 1
            if s.offer(key, msg(key, n, size=max(op[2], 6) if op[2] else 0)):
                offered_at[(key, n)] = clock.now()
                newest[key] = n
        elif op[0] == "tick":
            clock.advance(op[1])
        else:
            for _ in range(op[1]):
                picked = s.next_payload()
                if picked is None:
                    break
                key, payload = picked
                assert len(payload) <= 255
                if payload[:3] == b"\x00\x18\xfa":          # a fragment
                    started.setdefault(key, (clock.now(), newest[key]))
                    whole = r.feed(payload)
                    if whole is None:
                        continue
                    t0, newest_then = started.pop(key)
                else:
                    whole, t0, newest_then = payload, clock.now(), newest[key]
                sent.append((key, serial(whole), t0, newest_then))
        for key, c in s.stats().items():
            assert accounted(c) == c["offered"], (key, c)

    assert sum(c["offered"] for c in s.stats().values()) == n
    for key, pol in enumerate(policies):
        mine = [(m, t0, nw) for k, m, t0, nw in sent if k == key]
        serials = [m for m, _, _ in mine]
        assert len(serials) == len(set(serials)), "sent twice"
        assert serials == sorted(serials), "out of order"
        assert s.stats()[key]["sent"] == len(mine)
        for m, t0, nw in mine:
            if pol.ttl is not None:
                assert t0 - offered_at[(key, m)] <= pol.ttl + 1e-9, "sent stale"
            if pol.queue == "latest":
                assert m == nw, "latest channel sent an older message"
        if pol.rate is not None:
            times = [t0 for _, t0, _ in mine]
            assert all(b - a >= 1 / pol.rate - 1e-9 for a, b in zip(times, times[1:])), "rate exceeded"


# -- shares: a claim that grows with waiting, strict only where asked -------------------------

def served_keys(s: LinkScheduler, clock: ManualClock, n: int, step: float = 0.2) -> list[int]:
    out = []
    for _ in range(n):
        clock.advance(step)
        got = s.next_payload()
        if got is not None:
            out.append(got[0])
    return out


def test_saturated_channels_are_served_in_proportion_to_priority_plus_one():
    clock = ManualClock()
    s = LinkScheduler(clock)
    for key, prio in ((1, 0), (2, 1), (3, 3)):
        s.add_channel(key, LinkPolicy(queue="fifo", depth=5000, priority=prio))
        for n in range(3000):
            s.offer(key, msg(key, n % 200))
    keys = served_keys(s, clock, 4000)
    share = {k: keys.count(k) / len(keys) for k in (1, 2, 3)}
    assert abs(share[1] - 1 / 7) < 0.01 and abs(share[2] - 2 / 7) < 0.01 and abs(share[3] - 4 / 7) < 0.01


def test_a_flooding_top_priority_channel_no_longer_silences_the_others():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(1, LinkPolicy(queue="fifo", depth=1000, priority=10))
    for key in range(2, 6):
        s.add_channel(key, LinkPolicy(priority=0))
        s.offer(key, msg(key, 0))
    for n in range(1000):
        s.offer(1, msg(1, n % 200))
    keys = served_keys(s, clock, 20)
    assert set(keys) == {1, 2, 3, 4, 5}


def test_a_strict_channel_goes_before_all_others_whenever_it_is_ready():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(1, LinkPolicy(queue="fifo", depth=100, priority=0, strict=True))
    s.add_channel(2, LinkPolicy(queue="fifo", depth=100, priority=50))
    for n in range(10):
        s.offer(1, msg(1, n))
        s.offer(2, msg(2, n))
    assert served_keys(s, clock, 20) == [1] * 10 + [2] * 10


def test_a_channel_idle_for_long_is_served_at_once_when_a_message_comes():
    clock = ManualClock()
    s = LinkScheduler(clock)
    s.add_channel(1, LinkPolicy(queue="fifo", depth=100, priority=10))
    s.add_channel(2, LinkPolicy(priority=0))
    for n in range(100):
        s.offer(1, msg(1, n))
    served_keys(s, clock, 30)
    s.offer(2, msg(2, 0))
    assert served_keys(s, clock, 1) == [2]


def test_a_withdrawn_payload_never_leaves_and_the_others_keep_their_order():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10))
    for k in range(3):
        s.offer(4, msg(4, k))
    assert s.withdraw(4, msg(4, 1))
    assert s.stats()[4]["withdrawn"] == 1
    assert [s.next_payload(t) for t in (0.0, 1.0, 2.0)] == [(4, msg(4, 0)), (4, msg(4, 2)), None]


def test_withdrawing_a_payload_that_left_or_never_came_says_so():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10))
    s.offer(4, msg(4, 0))
    assert s.next_payload(0.0) == (4, msg(4, 0))
    assert not s.withdraw(4, msg(4, 0))
    assert not s.withdraw(9, msg(4, 0))
    assert s.stats()[4]["withdrawn"] == 0


def test_a_payload_waits_until_it_starts_to_leave():
    s = LinkScheduler(ManualClock())
    s.add_channel(4, LinkPolicy(queue="fifo", depth=10))
    s.offer(4, msg(4, 0))
    assert s.waiting(4, msg(4, 0)) and not s.waiting(4, msg(4, 1)) and not s.waiting(9, msg(4, 0))
    assert s.next_payload(0.0) == (4, msg(4, 0))
    assert not s.waiting(4, msg(4, 0))
