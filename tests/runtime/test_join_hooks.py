"""Joining reliability's and the seal's packet hooks into one (docs/seams.md section 5)."""
from __future__ import annotations

import pytest

from uwgen.runtime.wire import envelope
from uwgen.runtime.link.hooks import PacketHooks, join_hooks


def test_parts_of_joined_hooks_are_merged_and_overheads_added():
    a = PacketHooks(parts=lambda now: {"time": 5, "ack": b"\x01"}, overhead=7)
    b = PacketHooks(parts=lambda now: {"time": 5, "control": b"\x02"}, overhead=3)
    joined = join_hooks(a, None, b)
    assert joined.parts(0.0) == {"time": 5, "ack": b"\x01", "control": b"\x02"}
    assert joined.overhead == 10


def test_two_hooks_giving_one_part_different_values_fail_the_packet():
    joined = join_hooks(PacketHooks(parts=lambda now: {"ack": b"\x01"}),
                        PacketHooks(parts=lambda now: {"ack": b"\x02"}))
    with pytest.raises(envelope.EnvelopeError, match="ack"):
        joined.parts(0.0)


def test_a_time_both_hooks_stamp_keeps_the_first_a_tick_apart_is_no_conflict():
    joined = join_hooks(PacketHooks(parts=lambda now: {"time": 5}),
                        PacketHooks(parts=lambda now: {"time": 6, "control": b""}))
    assert joined.parts(0.0) == {"time": 5, "control": b""}


def test_sent_and_received_reach_every_hook_in_order():
    seen = []
    a = PacketHooks(sent=lambda n, msgs, now: seen.append(("a-sent", n)),
                    received=lambda e, now: seen.append(("a-received", e.number)))
    b = PacketHooks(sent=lambda n, msgs, now: seen.append(("b-sent", n)),
                    received=lambda e, now: seen.append(("b-received", e.number)))
    joined = join_hooks(a, b)
    joined.sent(4100, [], 1.0)
    joined.received(envelope.Envelope(1, 4), 1.0)
    assert seen == [("a-sent", 4100), ("b-sent", 4100), ("a-received", 4), ("b-received", 4)]


def test_the_one_sealing_hook_seals_and_opens_the_joined_packets():
    sealer = PacketHooks(seal=lambda e: b"sealed", open=lambda data: envelope.Envelope(2, 9))
    joined = join_hooks(PacketHooks(parts=lambda now: {}), sealer)
    assert joined.seal(envelope.Envelope(1, 1)) == b"sealed"
    assert joined.open(b"x") == envelope.Envelope(2, 9)
    assert join_hooks(PacketHooks()).seal is None and join_hooks().parts is None


def test_two_sealing_hooks_are_refused():
    with pytest.raises(ValueError, match="at most one"):
        join_hooks(PacketHooks(seal=lambda e: b""), PacketHooks(open=lambda d: None))


def test_the_sealer_numbers_packets_and_next_overheads_add_up():
    numbers = iter([7, 8])
    sealer = PacketHooks(seal=lambda e: e.encode(), number=lambda: next(numbers), overhead=23,
                         next_overhead=lambda now: 8)
    joined = join_hooks(PacketHooks(overhead=4), sealer)
    assert joined.number() == 7 and joined.next_overhead(0.0) == 4 + 8 and joined.overhead == 27
    assert join_hooks(PacketHooks(overhead=4)).next_overhead is None


def test_the_packer_uses_the_sealers_number_and_leaves_the_room_it_asks_for():
    from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer
    from uwgen.runtime.stats import Counters

    class Queue:
        items = [(4, bytes((0, 4)) + bytes(20)) for _ in range(5)]

        def next_payload(self, now, budget=None, exclude=None, *, fill=False, cut=None, **_):
            if not self.items or (budget is not None and 23 > budget) or cut is not None:
                return None                 # (nothing is cut: whole messages only)
            return self.items.pop(0)
    sent = []
    hooks = PacketHooks(number=lambda: 4096 + 3, overhead=30, next_overhead=lambda now: 0,
                        sent=lambda n, picked, now: sent.append((n, len(picked))))
    packer = Packer(Queue(), sender=1, max_read_length=64, hooks=hooks, counters=Counters(PACKET_COUNTERS))
    data = packer.next_packet(0.0)
    assert envelope.decode(data).number == 3 and sent == [(4099, 2)]   # 2 of 22 B fit 58 B, not 28


def test_reliabilitys_own_hooks_pass_through_the_join_and_timers_take_the_earliest():
    heads = PacketHooks(stamp=lambda k, p, born, now: p + b"!", admit=lambda p, now: p[:-1],
                        head_room=lambda k: 1, resend=lambda now, room: (4, b"again"),
                        ack_only=lambda now: now > 5, next_time=lambda now: now + 3,
                        stats=lambda: {"ledger": {4: {}}})
    other = PacketHooks(next_time=lambda now: now + 1, ack_only=lambda now: False,
                        stats=lambda: {"security": {}})
    joined = join_hooks(heads, other)
    assert joined.stamp(4, b"x", 0.0, 0.0) == b"x!" and joined.admit(b"x!", 0.0) == b"x"
    assert joined.resend(0.0, 10) == (4, b"again") and joined.head_room(4) == 1
    assert joined.next_time(10.0) == 11.0
    assert joined.ack_only(6.0) and not joined.ack_only(4.0)
    assert joined.stats() == {"ledger": {4: {}}, "security": {}}


def test_two_hooks_giving_message_heads_or_resends_are_refused():
    with pytest.raises(ValueError, match="message heads"):
        join_hooks(PacketHooks(admit=lambda p, now: p), PacketHooks(stamp=lambda *a: b""))
    with pytest.raises(ValueError, match="re-send"):
        join_hooks(PacketHooks(resend=lambda now, room: None), PacketHooks(resend=lambda now, room: None))
