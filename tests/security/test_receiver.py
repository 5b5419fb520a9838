"""The receiving rules as a pure class (security.receiver.Receiver), as wire format 2's packet
seal will use them: 12-bit packet numbers in W, the epoch and time in a sync packet."""
from __future__ import annotations

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.freshness import Freshness, stamp
from uwgen.security.receiver import Numbering, Receiver
from uwgen.security.wire import Sync

from .helpers import WALL0

EPOCH = bytes(range(6))


def receiver(wall=None):
    new_epochs = []
    r = Receiver({1: "surface"}, lambda sender, epoch: ("key", sender, epoch), Freshness(5.0),
                 ManualClock(), wall or ManualClock(WALL0), on_new_epoch=new_epochs.append)
    return r, new_epochs


def packet(number: int, sync: bool = False, time: float = WALL0) -> Numbering:
    return Numbering(1, number % 4096, 12, number if sync else None,
                     Sync(EPOCH, stamp(time)) if sync else None)


def genuine(aead, number):
    """A tag check that any number under the right key passes (the frames are the sender's)."""
    return ("packet", number) if aead == ("key", 1, EPOCH) else None


def test_packets_numbered_in_12_bits_follow_a_sync_packet():
    r, new_epochs = receiver()
    assert r.admit(packet(5000, sync=True), 120.0, genuine) == ("packet", 5000)
    assert new_epochs == [1]
    assert r.admit(packet(5001), 120.0, genuine) == ("packet", 5001)
    assert r.admit(packet(5001), 120.0, genuine) == "replay"
    assert r.admit(packet(4999), 120.0, genuine) == "replay"       # below the first: seen
    assert r.admit(packet(7001), 120.0, genuine) == ("packet", 7001)   # 2000 on: within 2048
    assert r.admit(packet(5001), 120.0, genuine) == "too_old"


def test_without_a_sync_packet_nothing_is_taken():
    r, _ = receiver()
    assert r.admit(packet(7), 120.0, genuine) == "unsynced"


def test_a_sync_packet_sealed_before_the_receiver_started_is_refused():
    r, _ = receiver()
    assert r.admit(packet(3, sync=True, time=WALL0 - 1.0), 120.0, genuine) == "before_start"


def test_a_bad_tag_changes_nothing():
    r, new_epochs = receiver()
    assert r.admit(packet(3, sync=True), 120.0, lambda aead, n: None) == "bad_tag"
    assert new_epochs == [] and r.peer(1).current is None


def only(*numbers_by_epoch):
    """A tag check that passes exactly the given (epoch, number) pairs: the real sender's and
    a key holder's frames, each valid only at its own number."""
    allowed = set(numbers_by_epoch)

    def verify(aead, number):
        return ("packet", aead[2], number) if (aead[2], number) in allowed else None
    return verify


def sync_of(epoch: bytes, number: int) -> Numbering:
    return Numbering(1, number % 4096, 12, number, Sync(epoch, stamp(WALL0)))


def test_a_key_holders_jump_inside_the_bound_does_not_lock_the_real_sender_out():
    r, _ = receiver()
    jump = 5001 + 60_000
    tags = only(*[(EPOCH, n) for n in range(5000, 5010)], (EPOCH, jump))
    assert r.admit(packet(5000, sync=True), 120.0, tags) == ("packet", EPOCH, 5000)
    assert r.admit(packet(5001), 120.0, tags) == ("packet", EPOCH, 5001)
    assert r.admit(sync_of(EPOCH, jump), 120.0, tags) == ("packet", EPOCH, jump)   # verified
    # the real sender goes on from where it was: taken under the window before the jump
    assert r.admit(packet(5002), 120.0, tags) == ("packet", EPOCH, 5002)
    assert r.admit(packet(5002), 120.0, tags) == "replay"
    assert r.admit(sync_of(EPOCH, 5003), 120.0, tags) == ("packet", EPOCH, 5003)
    assert r.admit(packet(5004), 120.0, tags) == ("packet", EPOCH, 5004)


def test_two_fresh_epochs_of_a_key_holder_do_not_push_the_real_epoch_out_for_good():
    r, _ = receiver()
    e2, e3 = bytes([9] * 6), bytes([8] * 6)
    tags = only(*[(EPOCH, n) for n in range(10, 20)], (e2, 0), (e3, 0))
    assert r.admit(sync_of(EPOCH, 10), 120.0, tags) == ("packet", EPOCH, 10)
    assert r.admit(sync_of(e2, 0), 120.0, tags) == ("packet", e2, 0)
    assert r.admit(sync_of(e3, 0), 120.0, tags) == ("packet", e3, 0)   # the real one let go
    assert r.admit(packet(11), 120.0, tags) == "bad_tag"              # until its next sync frame
    assert r.admit(sync_of(EPOCH, 12), 120.0, tags) == ("packet", EPOCH, 12)   # taken back
    assert r.admit(packet(13), 120.0, tags) == ("packet", EPOCH, 13)
    assert r.admit(sync_of(EPOCH, 10), 120.0, tags) == "replay"       # under its old window
