"""Replay window: duplicates and too-old frames are rejected, reordering inside the window
is accepted, and neither side's restart (with no state kept) lets an old frame in or keeps a
new one out."""
from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE
from uwgen.security.guard import SYNC_EVERY
from uwgen.security.window import REPLAY, TOO_OLD, WINDOW, ReplayWindow

from .helpers import WALL0, surface, twist, vehicle


def test_window_marks_duplicates_and_too_old():
    w = ReplayWindow(64)
    for seq in (10, 12, 11, 70):
        assert w.check(seq) == "new"
        w.accept(seq)
    assert w.check(11) == REPLAY and w.check(70) == REPLAY
    assert w.check(7) == "new"             # 70 - 7 = 63: the last position of the window, unseen
    assert w.check(6) == TOO_OLD           # 70 - 6 = 64: just below it
    assert w.check(69) == "new"


def test_reconstruction_picks_the_closest_number():
    w = ReplayWindow(high=5000)
    assert w.reconstruct(5001 & 2047) == 5001
    assert w.reconstruct(4990 & 2047) == 4990
    assert w.reconstruct((5000 + 1000) & 2047) == 6000
    assert ReplayWindow().reconstruct(3) is None


def test_replays_after_one_second_are_rejected(tmp_path):
    clock = ManualClock()
    s, v = surface(tmp_path), vehicle(tmp_path, clock=clock)
    frames = [s.protect(4, twist(i)) for i in range(20)]
    assert all(v.unprotect(f) is not None for f in frames)
    clock.advance(1.0)
    assert [v.unprotect(f) for f in frames] == [None] * 20
    assert v.stats()["replay"] == 20


def test_reordering_inside_the_window_is_accepted_once(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    frames = [(i, s.protect(4, twist(i))) for i in range(300)]
    v.unprotect(frames[0][1])
    rng = random.Random(3)
    order = frames[1:]
    # shuffle within blocks smaller than the window: every frame is inside it on arrival
    blocks = [order[k:k + 48] for k in range(0, len(order), 48)]
    for b in blocks:
        rng.shuffle(b)
    got = [v.unprotect(f) for b in blocks for _, f in b]
    assert all(g is not None for g in got)
    assert sorted(got) == sorted(twist(i) for i in range(1, 300))
    assert v.stats()["verified"] == 300 and v.stats()["dropped"] == 0


def test_reordering_outside_the_window_is_rejected(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    frames = [s.protect(4, twist(i)) for i in range(WINDOW + 10)]
    late, inside = frames[1], frames[WINDOW - 50]
    assert v.unprotect(frames[0]) is not None
    for f in frames[2:]:
        if f is not inside:
            assert v.unprotect(f) is not None
    assert v.unprotect(inside) == twist(WINDOW - 50)   # 60 behind the newest: accepted
    assert v.unprotect(late) is None                   # 136 behind: outside the window
    assert v.stats()["too_old"] == 1


@pytest.mark.parametrize("stop", ["clean", "crash"])
def test_a_receiver_restarted_without_state_takes_no_recorded_frame(tmp_path, stop):
    # Nothing is kept on disk: a restarted receiver takes a sender's epoch only from a sync
    # frame sealed after it started (its clock, give or take the tolerance).
    wall = ManualClock(WALL0)
    s, v = surface(tmp_path, wall=wall), vehicle(tmp_path, wall=wall)
    frames = [s.protect(4, twist(i)) for i in range(40)]
    for f in frames:
        assert v.unprotect(f) is not None
    if stop == "clean":
        v.close()
    else:
        v._lock_file.release()                  # killed: the kernel drops a dead process's lock
    wall.advance(CLOCK_TOLERANCE + 1.0)         # restarted a few seconds later
    v2 = vehicle(tmp_path, wall=wall)
    assert [v2.unprotect(f) for f in frames] == [None] * 40
    assert v2.stats()["before_start"] == 3 and v2.stats()["unsynced"] == 37   # 3 sync frames, 37 not
    live = [v2.unprotect(s.protect(4, twist(100 + i))) for i in range(SYNC_EVERY)]
    assert live[-1] == twist(100 + SYNC_EVERY - 1)      # heard again from its next sync frame
    assert v2.stats()["verified"] >= 1


def test_a_restarted_sender_starts_a_new_epoch_heard_at_once(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    for i in range(10):
        assert v.unprotect(s.protect(4, twist(i))) is not None
    s._lock_file.release()                      # crash: nothing of it is kept anywhere
    s2 = surface(tmp_path)
    assert s2.stats()["epoch"] != s.stats()["epoch"] and s2.stats()["next_seq"] == 0
    frames = [s2.protect(4, twist(i)) for i in range(10)]
    assert [v.unprotect(f) for f in frames] == [twist(i) for i in range(10)]
    assert v.stats()["epochs_seen"] == 2 and v.stats()["peers"]["1"]["epoch"] == s2.stats()["epoch"]


def test_a_receiver_that_missed_many_frames_resyncs_on_a_sync_frame(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    assert v.unprotect(s.protect(4, twist(0))) is not None
    for i in range(3000):                       # out of range: more than 1024 numbers pass
        s.protect(4, twist(i))
    got = [v.unprotect(s.protect(4, twist(i))) for i in range(64)]
    ok = [g is not None for g in got]
    assert any(ok) and ok[-1]                   # heard again within one sync period
    assert all(ok[ok.index(True):])


def test_a_fresh_receiver_waits_for_a_sync_frame(tmp_path):
    s = surface(tmp_path)
    for i in range(5):
        s.protect(4, twist(i))                  # the first three (sync) frames are lost
    (tmp_path / "v").mkdir()
    v = vehicle(tmp_path / "v")
    got = [v.unprotect(s.protect(4, twist(i))) for i in range(70)]   # a sync frame every 64
    assert v.stats()["unsynced"] > 0
    first = next(k for k, g in enumerate(got) if g is not None)
    assert all(g is not None for g in got[first:])


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 600), max_size=200), st.sampled_from([64, 128]))
def test_window_agrees_with_a_set_of_everything_seen(seqs, size):
    w = ReplayWindow(size)
    seen: set[int] = set()
    for seq in seqs:
        high = max(seen) if seen else None
        if high is not None and seq <= high - size:
            want = TOO_OLD
        elif seq in seen:
            want = REPLAY
        else:
            want = "new"
        assert w.check(seq) == want
        if want == "new":
            w.accept(seq)
            seen.add(seq)
