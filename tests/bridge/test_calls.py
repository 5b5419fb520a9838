"""The calling side's table of outstanding service calls (seq, timeouts, late answers)."""
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.bridge.calls import CallTable, CallTableFull
from uwgen.runtime.clock import ManualClock


def make(clock=None, seed=1, **kw):
    return CallTable(clock or ManualClock(), rng=random.Random(seed), **kw)


def test_sequence_starts_at_a_random_value_per_run():
    starts = {make(seed=s).begin(20, 10.0).seq for s in range(20)}
    assert len(starts) > 15  # different runs start at different seqs


def test_sequence_counts_up_and_wraps_at_the_modulus():
    table = make(seq_modulus=8, max_outstanding=4)
    seqs = []
    for _ in range(10):
        call = table.begin(20, 10.0)
        seqs.append(call.seq)
        assert table.complete(20, call.seq) is call
    assert all((b - a) % 8 == 1 for a, b in zip(seqs, seqs[1:]))
    assert all(0 <= s < 8 for s in seqs)


def test_each_service_id_has_its_own_sequence():
    table = make()
    a = table.begin(20, 10.0)
    b = table.begin(21, 10.0)
    assert table.complete(21, a.seq) is not a
    assert table.outstanding(20) == 1
    assert table.complete(21, b.seq) in (b, None)


def test_several_calls_outstanding_complete_in_any_order():
    clock = ManualClock()
    table = make(clock)
    calls = [table.begin(20, 10.0, token=i) for i in range(5)]
    assert len({c.seq for c in calls}) == 5
    clock.advance(1.5)
    for call in reversed(calls):
        assert table.complete(20, call.seq).token == call.token
    stats = table.stats()[20]
    assert stats["completed"] == 5 and stats["outstanding"] == 0
    assert table.stats_of(20).latencies == [1.5] * 5


def test_call_times_out_at_its_deadline_not_before():
    clock = ManualClock()
    table = make(clock)
    call = table.begin(20, 2.0)
    clock.advance(1.999)
    assert table.expire() == []
    clock.advance(0.001)
    assert table.expire() == [call]
    assert table.stats()[20]["timeouts"] == 1
    assert table.outstanding() == 0


def test_late_response_after_timeout_is_dropped_and_counted_as_late():
    clock = ManualClock()
    table = make(clock)
    call = table.begin(20, 1.0)
    clock.advance(1.0)
    table.expire()
    assert table.complete(20, call.seq) is None
    stats = table.stats()[20]
    assert (stats["late"], stats["duplicate"], stats["unknown"]) == (1, 0, 0)


def test_duplicate_response_is_dropped_and_counted():
    table = make()
    call = table.begin(20, 1.0)
    assert table.complete(20, call.seq) is call
    assert table.complete(20, call.seq) is None
    assert table.stats()[20]["duplicate"] == 1


def test_response_with_a_seq_never_issued_is_counted_unknown():
    table = make()
    call = table.begin(20, 1.0)
    assert table.complete(20, (call.seq + 100) % 65536) is None
    assert table.complete(21, call.seq) is None
    assert table.stats()[20]["unknown"] == 1
    assert table.stats()[21]["unknown"] == 1
    assert table.outstanding(20) == 1


def test_too_many_outstanding_calls_are_refused_and_counted():
    table = make(max_outstanding=2)
    table.begin(20, 1.0)
    table.begin(20, 1.0)
    with pytest.raises(CallTableFull, match="2 calls already outstanding"):
        table.begin(20, 1.0)
    assert table.stats()[20]["refused"] == 1
    table.begin(21, 1.0)  # another service is not affected


def test_abandoned_call_makes_its_response_late():
    table = make()
    call = table.begin(20, 1.0)
    assert table.abandon(20, call.seq) is call
    assert table.complete(20, call.seq) is None
    stats = table.stats()[20]
    assert stats["abandoned"] == 1 and stats["late"] == 1 and stats["outstanding"] == 0


def test_allocation_skips_seqs_still_outstanding_after_a_wrap():
    table = make(seq_modulus=4, max_outstanding=3)
    first = table.begin(20, 100.0)
    others = [table.begin(20, 1.0) for _ in range(2)]
    for c in others:
        table.complete(20, c.seq)
    # The counter wraps onto first.seq, which is still outstanding: it must be skipped.
    seqs = []
    for _ in range(4):
        c = table.begin(20, 1.0)
        seqs.append(c.seq)
        table.complete(20, c.seq)
    assert first.seq not in seqs
    assert table.complete(20, first.seq) is first


def test_next_deadline_is_the_earliest_outstanding():
    clock = ManualClock(5.0)
    table = make(clock)
    assert table.next_deadline() is None
    table.begin(20, 3.0)
    table.begin(21, 1.0)
    assert table.next_deadline() == 6.0


def test_finished_memory_is_bounded():
    table = make(memory=4)
    seqs = []
    for _ in range(10):
        c = table.begin(20, 1.0)
        table.complete(20, c.seq)
        seqs.append(c.seq)
    # The oldest are forgotten (then unknown), the newest still known as duplicates.
    assert table.complete(20, seqs[0]) is None
    assert table.complete(20, seqs[-1]) is None
    stats = table.stats()[20]
    assert stats["unknown"] == 1 and stats["duplicate"] == 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["call", "respond", "tick", "junk"]),
                          st.integers(0, 50)), max_size=80),
       st.integers(0, 2**32))
def test_every_response_is_delivered_once_or_counted(ops, seed):
    """Model check: a response completes its call at most once, never after the deadline,
    and every response that does not complete a call is counted exactly once."""
    clock = ManualClock()
    table = CallTable(clock, rng=random.Random(seed), seq_modulus=64, max_outstanding=8,
                      memory=1000)
    issued: list[int] = []
    live: set[int] = set()
    responses = delivered = 0
    for op, arg in ops:
        if op == "call":
            try:
                c = table.begin(7, timeout=1.0 + arg / 10)
            except CallTableFull:
                assert len(live) == 8
                continue
            assert c.seq not in live
            live.add(c.seq)
            issued.append(c.seq)
        elif op == "respond" and issued:
            seq = issued[arg % len(issued)]
            responses += 1
            call = table.complete(7, seq)
            if call is not None:
                assert seq in live and call.deadline > clock.now()
                live.discard(seq)
                delivered += 1
        elif op == "junk":
            responses += 1
            assert table.complete(7, 64 + arg) is None
        elif op == "tick":
            clock.advance(arg / 10)
            for c in table.expire():
                live.discard(c.seq)
    s = table.stats_of(7)
    assert s.completed == delivered
    assert s.completed + s.late + s.duplicate + s.unknown == responses
    assert table.outstanding(7) == len(live)


# -- per-service seq ranges (rmw_desert: 1..999) ------------------------------------------

def test_a_service_can_be_given_its_own_seq_range():
    table = make()
    table.set_seq_range(20, 1, 999)
    seqs = [table.begin(20, 10.0).seq for _ in range(30)]
    assert all(1 <= s <= 999 for s in seqs)
    assert table.seq_range(20) == (1, 999)
    assert table.seq_range(21) == (0, 65535)  # other services keep the default


def test_seq_range_wraps_from_last_to_first_and_never_gives_zero():
    table = make(max_outstanding=4, seed=7)
    table.set_seq_range(20, 1, 5)
    seqs = []
    for _ in range(12):
        call = table.begin(20, 10.0)
        seqs.append(call.seq)
        table.complete(20, call.seq)
    assert set(seqs) == {1, 2, 3, 4, 5}
    assert all(b == (a % 5) + 1 for a, b in zip(seqs, seqs[1:]))


def test_seq_range_must_hold_more_seqs_than_can_be_outstanding():
    table = make(max_outstanding=4)
    with pytest.raises(ValueError, match="more than 4 seqs"):
        table.set_seq_range(20, 1, 4)
    with pytest.raises(ValueError, match="empty"):
        table.set_seq_range(20, 9, 3)
    table.set_seq_range(20, 1, 5)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2000), st.integers(5, 1200), st.integers(0, 2**32),
       st.lists(st.booleans(), max_size=60))
def test_seqs_stay_in_their_range_and_unique_among_outstanding(first, size, seed, completes):
    table = CallTable(ManualClock(), rng=random.Random(seed), max_outstanding=4)
    last = first + size - 1
    table.set_seq_range(3, first, last)
    live: list[int] = []
    for complete in completes:
        if complete and live:
            assert table.complete(3, live.pop(0)) is not None
        elif len(live) < 4:
            seq = table.begin(3, 10.0).seq
            assert first <= seq <= last and seq not in live
            live.append(seq)


def test_server_answering_only_the_latest_call_times_the_older_ones_out():
    """An rmw_desert server may keep only the newest request: the newest call completes,
    the older ones time out at their deadlines and count as timeouts, and an answer that
    still comes for one of them later counts as late."""
    clock = ManualClock()
    table = make(clock)
    table.set_seq_range(20, 1, 999)
    calls = [table.begin(20, 2.0, token=i) for i in range(3)]
    clock.advance(0.5)
    assert table.complete(20, calls[-1].seq) is calls[-1]
    clock.advance(1.0)
    assert table.expire() == []              # not before their deadline
    clock.advance(0.5)
    assert table.expire() == calls[:2]
    assert table.complete(20, calls[0].seq) is None
    stats = table.stats()[20]
    assert (stats["completed"], stats["timeouts"], stats["late"], stats["outstanding"]) == (1, 2, 1, 0)


def test_reuse_after_rests_a_finished_seq_while_another_is_free():
    clock = ManualClock()
    table = CallTable(clock, rng=random.Random(1), max_outstanding=2, reuse_after=10.0)
    table.set_seq_range(9, 0, 2)                      # three seqs, at most two outstanding
    a = table.begin(9, 5.0).seq
    table.complete(9, a)
    b = table.begin(9, 5.0).seq
    c = table.begin(9, 5.0).seq
    assert a not in (b, c)                             # the rested seq is skipped...
    table.complete(9, b)
    d = table.begin(9, 5.0).seq                        # ...unless only rested ones are free
    assert d in (a, b)
    clock.advance(10.0)
    table.complete(9, c)
    table.complete(9, d)
    # c and d just ended; of a and b, the one d did not take has rested 10 s: it is next.
    assert {table.begin(9, 5.0).seq} == {a, b} - {d}
