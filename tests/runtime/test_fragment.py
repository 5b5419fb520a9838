"""Fragments: layout, round trips, loss, timeout, inconsistency, duplicates and bounded memory."""
from __future__ import annotations

import random

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.fragment import (Fragment, FragmentError, Fragmenter, encode_fragment,
                                         is_fragment, parse_fragment)
from uwgen.runtime.wire.reassembly import Reassembler
from uwgen.runtime.wire.framing import FrameDecoder, encode_frame

FID = 250


def big(n: int, seed: int = 0) -> bytes:
    """A payload as a codec would make it: kind 0, id 7, then bytes."""
    return b"\x00\x07" + random.Random(seed).randbytes(n - 2)


def cbor_items(payload: bytes) -> list:
    """Decode a CBOR sequence with the reference library."""
    import io
    f = io.BytesIO(payload)
    dec = cbor2.CBORDecoder(f)
    out = []
    while f.tell() < len(payload):
        out.append(dec.decode())
    return out


# -- layout --------------------------------------------------------------------------------------

def test_fragment_layout_is_a_cbor_sequence_kind_0_on_fragment_id():
    parts = Fragmenter(FID, rng=random.Random(3)).split(big(600))
    items = [cbor_items(p) for p in parts]
    transfer = items[0][2]
    assert [it[:2] for it in items] == [[0, FID]] * len(parts)
    assert [it[2] for it in items] == [transfer] * len(parts)
    assert [it[3] for it in items] == list(range(len(parts)))
    assert [it[4] for it in items] == [len(parts)] * len(parts)
    assert b"".join(it[5] for it in items) == big(600)


def test_fragment_bytes_for_a_small_example():
    f = encode_fragment(FID, Fragment(transfer=5, index=1, count=2, chunk=b"\x01\x02"))
    assert f == bytes.fromhex("00 18 FA 05 01 02 42 01 02")


def test_every_fragment_fits_one_frame_and_uses_the_room():
    fr = Fragmenter(FID, rng=random.Random(0))
    for size in (256, 300, 1000, 5000, fr.max_message_size):
        parts = fr.split(big(size))
        assert all(len(p) <= 255 for p in parts)
        assert all(len(p) >= 250 for p in parts[:-1]), "fragments should be nearly full"
        encode_frame(parts[0])          # does not raise


def test_fragmenter_counts_transfers_modulo_256_from_a_random_start():
    fr = Fragmenter(FID, rng=random.Random(9))
    first = parse_fragment(fr.split(big(300))[0], FID).transfer
    seen = [parse_fragment(fr.split(big(300))[0], FID).transfer for _ in range(300)]
    assert seen[:3] == [(first + 1) % 256, (first + 2) % 256, (first + 3) % 256]
    assert max(seen) == 255 and min(seen) == 0


def test_fragmenter_refuses_what_would_need_too_many_fragments():
    fr = Fragmenter(FID, max_fragments=4)
    fr.split(big(fr.max_message_size))
    with pytest.raises(FragmentError, match="more than 4 fragments"):
        fr.split(big(fr.max_message_size + 1))


def test_is_fragment_checks_kind_and_id():
    part = Fragmenter(FID).split(big(400))[0]
    assert is_fragment(part, FID)
    assert not is_fragment(part, 7)
    assert not is_fragment(part, None)
    assert not is_fragment(b"\x00\x18\xfb", FID)
    assert not is_fragment(b"\x02\x18\xfa", FID)
    assert is_fragment(b"\x00\x05\x01", 5) and not is_fragment(b"\x00\x05\x01", 250)


@pytest.mark.parametrize("payload, message", [
    (bytes.fromhex("01 18 FA 00 00 02 41 00"), "kind 1"),
    (bytes.fromhex("00 18 FB 00 00 02 41 00"), "id 251"),
    (bytes.fromhex("00 18 FA 00 02 02 41 00"), "index 2 not below count 2"),
    (bytes.fromhex("00 18 FA 00 00 00 41 00"), "count 0"),
    (bytes.fromhex("00 18 FA 19 01 00 00 02 41 00"), "transfer 256"),
    (bytes.fromhex("00 18 FA 00 00 02 40"), "empty chunk"),
    (bytes.fromhex("00 18 FA 00 00 02 42 00"), "chunk of 2 bytes but 1"),
    (bytes.fromhex("00 18 FA 00 00 02 41 00 00"), "chunk of 1 bytes but 2"),
    (bytes.fromhex("00 18 FA 00 00 02 61 00"), "chunk has CBOR major type 3"),
    (bytes.fromhex("00 18 FA 00 00"), "count missing"),
    (bytes.fromhex("00 18"), "id truncated"),
    (bytes.fromhex("00 18 FA 00 00 1C"), "additional info 28"),
])
def test_parse_fragment_rejects_malformed_input_with_a_reason(payload, message):
    with pytest.raises(FragmentError, match=message):
        parse_fragment(payload, FID)


@given(st.binary(max_size=40))
def test_parse_fragment_is_total(data):
    try:
        parse_fragment(data, FID)
    except FragmentError:
        pass


# -- reassembly ----------------------------------------------------------------------------------

@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=256, max_size=4000), st.randoms(use_true_random=False))
def test_round_trip_in_any_order(payload, rnd):
    parts = Fragmenter(FID, rng=rnd).split(payload)
    rnd.shuffle(parts)
    r = Reassembler(FID, ManualClock())
    out = [m for p in parts if (m := r.feed(p)) is not None]
    assert out == [payload]
    assert r.pending == 0 and r.buffered_bytes == 0 and r.stats["completed"] == 1


def test_round_trip_through_frames_and_decoder_cut_in_64_byte_packets():
    fr, r, d = Fragmenter(FID), Reassembler(FID, ManualClock()), FrameDecoder()
    messages = [big(n, seed=n) for n in (256, 700, 2000)]
    stream = b"".join(encode_frame(p) for m in messages for p in fr.split(m))
    out = []
    for i in range(0, len(stream), 64):
        for payload in d.feed(stream[i:i + 64]):
            if (m := r.feed(payload)) is not None:
                out.append(m)
    assert out == messages


def test_interleaved_transfers_reassemble_independently():
    fr = Fragmenter(FID)
    a, b = fr.split(big(600, 1)), fr.split(big(600, 2))
    r = Reassembler(FID, ManualClock())
    out = [m for pair in zip(a, b) for p in pair if (m := r.feed(p)) is not None]
    assert out == [big(600, 1), big(600, 2)]


def test_lost_fragment_drops_the_message_after_the_timeout():
    clock = ManualClock()
    fr, r = Fragmenter(FID), Reassembler(FID, clock, timeout=5.0)
    parts = fr.split(big(800))
    for p in parts[:-1]:
        assert r.feed(p) is None
    clock.advance(4.9)
    assert r.expire() == 0 and r.pending == 1
    clock.advance(0.2)
    assert r.expire() == 1
    assert r.pending == 0 and r.buffered_bytes == 0 and r.stats["timed_out"] == 1
    assert r.feed(parts[-1]) is None        # the late fragment alone cannot complete anything
    assert r.stats["completed"] == 0


def test_timeout_counts_from_the_last_fragment_not_the_first():
    clock = ManualClock()
    r = Reassembler(FID, clock, timeout=5.0)
    parts = Fragmenter(FID).split(big(1200))
    for p in parts:
        clock.advance(3.0)                  # a slow link: 3 s between fragments, 15 s in all
        out = r.feed(p)
    assert out == big(1200) and r.stats["timed_out"] == 0


def test_later_messages_still_arrive_after_a_lost_fragment():
    clock = ManualClock()
    fr, r = Fragmenter(FID), Reassembler(FID, clock, timeout=2.0)
    first, second = fr.split(big(600, 1)), fr.split(big(600, 2))
    out = [m for p in first[1:] + second if (m := r.feed(p)) is not None]
    assert out == [big(600, 2)]
    clock.advance(3)
    r.expire()
    assert r.stats["timed_out"] == 1 and r.pending == 0


def test_duplicate_fragment_is_ignored_and_counted():
    r = Reassembler(FID, ManualClock())
    parts = Fragmenter(FID).split(big(600))
    assert r.feed(parts[0]) is None and r.feed(parts[0]) is None
    out = [r.feed(p) for p in parts[1:]]
    assert out[-1] == big(600) and r.stats["duplicate"] == 1 and r.stats["completed"] == 1


def test_message_is_never_delivered_twice():
    r = Reassembler(FID, ManualClock())
    parts = Fragmenter(FID).split(big(600))
    delivered = [m for _ in range(2) for p in parts if (m := r.feed(p)) is not None]
    assert delivered == [big(600)]
    assert r.stats["duplicate"] == 1


def test_conflicting_bytes_for_one_fragment_drop_the_partial_and_start_over():
    r = Reassembler(FID, ManualClock())
    p0 = parse_fragment(Fragmenter(FID, rng=random.Random(1)).split(big(600))[0], FID)
    other = encode_fragment(FID, Fragment(p0.transfer, 0, p0.count, bytes(len(p0.chunk))))
    r.feed(encode_fragment(FID, p0))
    assert r.feed(other) is None
    assert r.stats["inconsistent"] == 1 and r.pending == 1


@pytest.mark.parametrize("second", [
    Fragment(7, 1, 4, b"x" * 100),        # another count
    Fragment(7, 1, 3, b"x" * 90),         # a middle chunk of another length
    Fragment(7, 2, 3, b"x" * 101),        # a last chunk longer than the others
])
def test_inconsistent_fragments_are_rejected_and_counted(second):
    r = Reassembler(FID, ManualClock())
    r.feed(encode_fragment(FID, Fragment(7, 0, 3, b"y" * 100)))
    assert r.feed(encode_fragment(FID, second)) is None
    assert r.stats["inconsistent"] == 1
    # The newer fragment started a fresh partial message: the old one is gone.
    assert r.pending == 1 and r.buffered_bytes == len(second.chunk)


def test_malformed_fragment_is_counted_not_raised():
    r = Reassembler(FID, ManualClock())
    assert r.feed(b"\x00\x18\xfa\x00") is None
    assert r.stats["malformed"] == 1


def test_partial_messages_are_bounded_in_number_oldest_evicted():
    clock = ManualClock()
    fr, r = Fragmenter(FID), Reassembler(FID, clock, max_transfers=3)
    firsts = [fr.split(big(600, i)) for i in range(5)]
    for parts in firsts:
        clock.advance(0.1)
        r.feed(parts[0])
        assert r.pending <= 3
    assert r.stats["evicted"] == 2
    # The newest three can still complete; the two oldest lost their first fragment for good.
    out = [m for parts in firsts[2:] for p in parts[1:] if (m := r.feed(p)) is not None]
    assert out == [big(600, i) for i in (2, 3, 4)]
    assert all(r.feed(p) is None for parts in firsts[:2] for p in parts[1:])


def test_partial_messages_are_bounded_in_bytes():
    clock = ManualClock()
    fr, r = Fragmenter(FID), Reassembler(FID, clock, max_bytes=1000)
    for i in range(6):
        clock.advance(0.1)
        for p in fr.split(big(900, i))[:-1]:
            r.feed(p)
            assert r.buffered_bytes <= 1000
    assert r.stats["evicted"] >= 5


def test_message_larger_than_the_memory_bound_is_refused():
    r = Reassembler(FID, ManualClock(), max_bytes=1000)
    parts = Fragmenter(FID).split(big(3000))
    assert all(r.feed(p) is None for p in parts)
    assert r.stats["oversized"] >= 1 and r.buffered_bytes <= 1000 and r.stats["completed"] == 0


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(256, 3000), st.booleans()), min_size=1, max_size=8),
       st.randoms(use_true_random=False))
def test_with_random_fragment_loss_only_complete_messages_arrive_once(messages, rnd):
    clock = ManualClock()
    fr, r = Fragmenter(FID, rng=rnd), Reassembler(FID, clock, timeout=10, max_transfers=3, max_bytes=6000)
    expected, delivered = [], []
    for k, (size, lose) in enumerate(messages):
        payload = big(size, k)
        parts = fr.split(payload)
        if lose:
            del parts[rnd.randrange(len(parts))]
        else:
            expected.append(payload)
        for p in parts:
            clock.advance(0.5)
            if (m := r.feed(p)) is not None:
                delivered.append(m)
            assert r.pending <= 3 and r.buffered_bytes <= 6000
    clock.advance(11)
    r.expire()
    assert delivered == expected
    assert r.pending == 0 and r.buffered_bytes == 0
    assert r.stats["timed_out"] + r.stats["evicted"] == sum(lose for _, lose in messages)


def test_a_message_lost_on_the_link_is_attributed_to_its_id_when_fragment_0_came():
    clock = ManualClock()
    reasm = Reassembler(FID, clock, timeout=5.0)
    first = Fragmenter(FID, rng=random.Random(1)).split(b"\x00\x07" + big(600))
    other = Fragmenter(FID, rng=random.Random(2)).split(b"\x02\x18\x2a\x05" + big(600))
    reasm.feed(first[0])                   # topic 7: fragment 0 came, the rest never did
    reasm.feed(other[1])                   # its fragment 0 was lost: whose message is unknown
    clock.advance(5.0)
    assert reasm.expire() == 2
    assert reasm.lost_by_id == {7: 1} and reasm.lost_unattributed == 1


# -- the compact fragment message of wire format 2 -------------------------------------------

from uwgen.runtime.wire.fragment import encode_compact, parse_any, parse_compact  # noqa: E402


@pytest.mark.parametrize("payload, message", [
    (b"\x61\x01\x00\x02", "at least"),
    (b"\x60\x01\x00\x02\x05", "H is not 61"),
    (b"\x61\x01\x00\x00\x05", "count 0"),
    (b"\x61\x01\x03\x02\x00", "no size and chunk"),
    (b"\x61\x01\x03\x02\x00\x09\xAA", "cannot be 2 chunks"),
])
def test_parse_compact_rejects_malformed_input_with_a_reason(payload, message):
    with pytest.raises(FragmentError, match=message):
        parse_compact(payload)


@given(st.binary(max_size=40))
def test_parse_compact_is_total(data):
    try:
        f = parse_compact(b"\x61" + data)
    except FragmentError:
        return
    assert encode_compact(f) == b"\x61" + data          # one encoding for what it accepts


@given(st.binary(max_size=40))
def test_a_reassembler_fed_any_compact_bytes_counts_and_never_raises(data):
    r = Reassembler(FID, ManualClock())
    whole = r.feed(b"\x61" + data)
    # refused and counted, or a fragment held, or a one-fragment message delivered
    assert r.stats["malformed"] + r.pending + r.stats["completed"] == 1
    assert (whole is not None) == (r.stats["completed"] == 1)


@settings(max_examples=150, deadline=None)
@given(st.binary(min_size=60, max_size=3000), st.integers(0, 3), st.randoms(use_true_random=False))
def test_compact_fragments_round_trip_with_repair_and_any_loss_within_it(payload, repair, rnd):
    fr = Fragmenter(FID, rng=rnd, max_payload=57, compact=True)
    parts = fr.split(payload, repair) if repair else fr.split(payload)
    assert all(p[:1] == b"\x61" and len(p) <= 57 for p in parts)
    assert all(is_fragment(p, FID, compact=True) and not is_fragment(p, FID) for p in parts)
    k = len(parts) - repair
    for i in rnd.sample(range(len(parts)), repair):     # lose as many as there are repairs
        parts[i] = None
    r = Reassembler(FID, ManualClock())
    out = [m for p in parts if p is not None and (m := r.feed(p)) is not None]
    assert out == [payload] and r.stats["malformed"] == 0
    assert all(parse_any(p, FID).count == k for p in parts if p is not None)


def test_compact_chunks_are_larger_than_wire_format_1_ones_in_the_same_room():
    compact = Fragmenter(FID, max_payload=57, compact=True)      # room 58, one length byte
    cbor = Fragmenter(FID, max_payload=58)
    assert compact.plan(2000) == (38, 53) and cbor.plan(2000)[1] == 47
