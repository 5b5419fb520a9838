"""Nonce uniqueness and freshness with no state on disk (docs/seams.md section 2): every start of a
sender is a new epoch and so a new key; receivers take an epoch only from a fresh sync frame and
refuse frames older than their entry's max age."""
from __future__ import annotations

import pytest

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.codec import pack_items
from uwgen.security import guard as guard_module
from uwgen.security import wire
from uwgen.security.epochs import PeerEpoch, PeerEpochs, SendSession
from uwgen.runtime.delivery.freshness import CLOCK_TOLERANCE, MAX_AGE, Freshness, sent_at, stamp
from uwgen.security.guard import GuardConfig, LinkGuard

from .helpers import KEY, MODES, WALL0, config, surface, twist, vehicle


@pytest.fixture
def nonces(monkeypatch):
    """Every (working key, nonce) any guard seals with, in order."""
    used: list[tuple[bytes, bytes]] = []
    real_seal = wire.seal

    def recording_seal(aead, mode, sender, seq, payload, fingerprint=b"", sync=None):
        used.append((aead_keys[id(aead)], wire.nonce(sender, seq)))
        return real_seal(aead, mode, sender, seq, payload, fingerprint, sync)
    aead_keys: dict[int, bytes] = {}
    real_new = wire.new_aead

    def recording_new(key, *tag):
        aead = real_new(key, *tag)
        aead_keys[id(aead)] = key
        keep.append(aead)                           # ids stay unique while recorded
        return aead
    keep: list = []
    monkeypatch.setattr(guard_module.wire, "seal", recording_seal)
    monkeypatch.setattr(guard_module.wire, "new_aead", recording_new)
    return used


def test_restarts_copies_and_renumbered_ids_never_repeat_a_nonce(tmp_path, nonces):
    # No lock path: as on separate machines, or with the state of an earlier design deleted,
    # restored from an image or copied: nothing on disk is read, so none of it matters.
    for start in range(200):
        sender = 1 if start % 3 else 3               # the same side renumbered now and then
        g = LinkGuard(KEY, config(sender, 2, "vehicle"), wall=ManualClock(WALL0))
        twin = LinkGuard(KEY, config(sender, 2, "vehicle"), wall=ManualClock(WALL0))  # a 2nd copy
        for i in range(20):
            g.protect(4, twist(i))
            twin.protect(4, twist(i))
    assert len(nonces) == 200 * 2 * 20
    assert len(set(nonces)) == len(nonces), "a (key, nonce) pair was used twice"


def test_two_copies_of_a_side_on_two_machines_are_both_heard_without_harm(tmp_path):
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    one, two, v = surface(tmp_path / "a"), surface(tmp_path / "b"), vehicle(tmp_path)
    assert one.stats()["epoch"] != two.stats()["epoch"]
    got = [v.unprotect(g.protect(4, twist(i))) for i in range(3) for g in (one, two)]
    assert got == [twist(i) for i in range(3) for _ in (one, two)]


def test_a_sender_starts_a_new_epoch_when_one_is_used_up(tmp_path):
    s, v = surface(tmp_path, epoch_numbers=100), vehicle(tmp_path)
    got = [v.unprotect(s.protect(4, twist(i))) for i in range(250)]
    assert got == [twist(i) for i in range(250)]
    assert s.session.epochs_started == 3 and v.stats()["epochs_seen"] == 3


def test_a_sync_frame_older_than_the_max_age_is_stale(tmp_path):
    wall = ManualClock(WALL0)
    s, v = surface(tmp_path), vehicle(tmp_path, wall=wall)
    frame = s.protect(4, twist(1.0))                     # sealed at WALL0
    wall.advance(MAX_AGE + CLOCK_TOLERANCE + 1.0)
    assert v.unprotect(frame) is None and v.stats()["stale"] == 1


def test_a_sync_frame_from_a_clock_far_ahead_is_refused(tmp_path):
    s = surface(tmp_path, wall=ManualClock(WALL0 + CLOCK_TOLERANCE + 1.0))
    v = vehicle(tmp_path)
    assert v.unprotect(s.protect(4, twist(1.0))) is None and v.stats()["stale"] == 1


def test_the_entrys_ttl_is_its_max_age(tmp_path):
    wall = ManualClock(WALL0)
    cfg = GuardConfig("demo", 2, {1: "surface"}, dict(MODES), {4: bytes.fromhex("a1b2c3d4e5f60718")},
                      max_ages={4: 2.0})
    v = LinkGuard(KEY, cfg, wall=wall)
    s = surface(tmp_path)
    frame = s.protect(4, twist(1.0))
    wall.advance(2.0 + CLOCK_TOLERANCE + 0.5)            # past cmd_vel's 2 s (and the tolerance)
    assert v.unprotect(frame) is None and v.stats()["stale"] == 1


def test_a_frame_held_back_while_newer_ones_went_through_is_stale(tmp_path):
    clock = ManualClock()
    s, v = surface(tmp_path), vehicle(tmp_path, clock=clock)
    frames = [s.protect(4, twist(i)) for i in range(10)]
    held, late_ok = frames[5], frames[6]
    for k, f in enumerate(frames):
        if k not in (5, 6):
            assert v.unprotect(f) == twist(k)
    clock.advance(1.0)
    assert v.unprotect(late_ok) == twist(6)              # reordered by a second: fine
    clock.advance(MAX_AGE)
    assert v.unprotect(held) is None and v.stats()["stale"] == 1   # overtaken 121 s ago


def test_a_receiver_keeps_the_last_two_epochs_of_a_sender():
    pe = PeerEpochs()
    a, b, c = (PeerEpoch(bytes([k]) * 6, None, None) for k in (1, 2, 3))
    for e in (a, b, a, c):
        pe.touch(e)
    assert [e.epoch for e in pe.recent()] == [c.epoch, a.epoch]


def test_a_session_counts_in_memory_from_zero_under_a_new_epoch():
    epochs = iter([b"\x01" * 6, b"\x02" * 6])
    sess = SendSession(lambda e: ("aead", e), lambda: next(epochs), limit=2)
    assert [sess.take() for _ in range(3)] == [0, 1, 0]
    assert sess.epoch == b"\x02" * 6 and sess.aead == ("aead", b"\x02" * 6)


def test_the_time_reads_back_near_the_receivers_clock_across_the_wrap():
    span = (1 << 24) / 32
    for wall in (WALL0, WALL0 + span - 0.01, 123.0):
        for offset in (-100.0, -1.0, 0.0, 3.0):
            assert sent_at(stamp(wall + offset), wall) == pytest.approx(wall + offset, abs=1 / 32)
    f = Freshness(5.0)
    assert f.fresh(stamp(WALL0 - 10), WALL0, 10.0) and not f.fresh(stamp(WALL0 - 16), WALL0, 10.0)


def test_a_restarted_peer_that_sends_is_answered_with_sync_frames_at_once(tmp_path):
    wall = ManualClock(WALL0)
    s, v = surface(tmp_path, wall=wall), vehicle(tmp_path, wall=wall)
    for i in range(10):
        assert v.unprotect(s.protect(4, twist(i))) is not None
    v.close()
    wall.advance(1.0)
    v2 = vehicle(tmp_path, wall=wall)
    assert v2.unprotect(s.protect(4, twist(10))) is None          # no sync frame: unsynced
    assert s.unprotect(v2.protect(7, pack_items([0, 7, "back"]))) is not None   # v2's new epoch
    assert v2.unprotect(s.protect(4, twist(11))) == twist(11)     # so s sends a sync frame now
    assert v2.stats()["unsynced"] == 1


def test_a_frame_sealed_a_moment_before_the_receiver_started_is_refused(tmp_path):
    wall = ManualClock(WALL0)
    s = surface(tmp_path, wall=wall)
    frame = s.protect(4, twist(1.0))
    wall.advance(0.1)                                   # well within the clock tolerance
    v = vehicle(tmp_path, wall=wall)
    assert v.unprotect(frame) is None and v.stats()["before_start"] == 1


def test_a_sync_frame_of_an_epoch_let_go_is_not_taken_again(tmp_path):
    # The receiver keeps 2 epochs per sender; a recorded sync frame of a third, older one must
    # not become a "new" epoch again (it would be delivered twice): the epoch let go is taken
    # back only under the window it had, where that frame is a replay.
    s, v = surface(tmp_path, epoch_numbers=10), vehicle(tmp_path)
    frames = [s.protect(4, twist(float(i))) for i in range(30)]      # 3 epochs of 10
    assert all(v.unprotect(f) is not None for f in frames)
    assert v.unprotect(frames[0]) is None and v.stats()["replay"] == 1
