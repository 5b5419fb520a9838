"""What one frame can do is bounded (docs/seams.md section 2): a key holder's frame numbered far ahead
(2^42) is refused as too_far and moves nothing, so the real sender is never locked out."""
from __future__ import annotations

from uwgen.security import wire
from uwgen.runtime.delivery.freshness import stamp
from uwgen.security.keys import working_key
from uwgen.security.window import MAX_JUMP, NEW, TOO_FAR, ReplayWindow

from .helpers import KEY, SURFACE, WALL0, surface, twist, vehicle


def forged(seq: int, epoch: bytes) -> bytes:
    """A fresh sync frame a key holder (any side of the network) can make in the surface's name."""
    aead = wire.new_aead(working_key(KEY, "demo", SURFACE, epoch))
    return wire.seal(aead, "encrypt", SURFACE, seq, twist(9.0), bytes.fromhex("a1b2c3d4e5f60718"),
                     wire.Sync(epoch, stamp(WALL0)))


def test_a_push_to_2_42_in_the_senders_epoch_is_refused_and_the_sender_goes_on(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    assert v.unprotect(s.protect(4, twist(1.0))) == twist(1.0)
    epoch = bytes.fromhex(s.stats()["epoch"])              # announced in every sync word
    assert v.unprotect(forged(2 ** 42, epoch)) is None
    assert v.stats()["too_far"] == 1
    for x in range(2, 200):
        assert v.unprotect(s.protect(4, twist(float(x)))) == twist(float(x))


def test_a_new_epoch_cannot_start_far_ahead(tmp_path):
    s, v = surface(tmp_path), vehicle(tmp_path)
    assert v.unprotect(forged(2 ** 42, bytes(6))) is None
    assert v.stats()["too_far"] == 1 and v.stats()["peers"] == {}


def test_the_window_refuses_more_than_the_stated_jump():
    w = ReplayWindow()
    w.accept(100)
    assert w.check(100 + MAX_JUMP) == NEW
    assert w.check(101 + MAX_JUMP) == TOO_FAR
    assert w.check(2 ** 42) == TOO_FAR and w.high == 100
