"""Framing: byte vectors of wire format section 2 and properties of the resynchronising decoder."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.runtime.wire.framing import MAX_PENDING, FrameDecoder, FrameError, encode_frame

from .framing_reference import reference_frames

H = bytes.fromhex


# -- encoder ---------------------------------------------------------------------------------

def test_encode_frame_matches_captured_rmw_desert_frames():
    assert encode_frame(H("00 0B 62 68 69")) == H("99 99 05 00 0B 62 68 69 55")
    assert encode_frame(H("00 0B 00")) == H("99 99 03 00 0B 00 55")
    assert encode_frame(H("02 0D 19 01 4A F5")) == H("99 99 06 02 0D 19 01 4A F5 55")


def test_encode_frame_accepts_bytearray_and_memoryview():
    assert encode_frame(bytearray(b"\x01")) == H("99 99 01 01 55")
    assert encode_frame(memoryview(b"\x01\x02")) == H("99 99 02 01 02 55")


def test_encode_frame_takes_255_bytes():
    frame = encode_frame(bytes(255))
    assert frame[:3] == H("99 99 FF") and frame[-1] == 0x55 and len(frame) == 259


@pytest.mark.parametrize("size", [0, 256, 1000])
def test_encode_frame_refuses_payload_that_does_not_fit(size):
    with pytest.raises(FrameError, match=f"1 to 255 bytes, got {size}"):
        encode_frame(bytes(size))


def test_encode_frame_refusal_of_long_payload_suggests_fragmenting():
    with pytest.raises(FrameError, match="fragment"):
        encode_frame(bytes(300))


# -- decoder: examples -----------------------------------------------------------------------

def test_decoder_delivers_one_frame():
    d = FrameDecoder()
    assert d.feed(H("99 99 05 00 0B 62 68 69 55")) == [H("00 0B 62 68 69")]
    assert d.stats.frames == 1 and d.stats.bytes_discarded == 0 and d.buffered == 0


def test_decoder_reassembles_frame_split_at_every_position():
    frame = encode_frame(b"\x00\x04hello")
    for cut in range(len(frame) + 1):
        d = FrameDecoder()
        assert d.feed(frame[:cut]) + d.feed(frame[cut:]) == [b"\x00\x04hello"], cut


def test_decoder_reassembles_frame_fed_one_byte_at_a_time():
    frames = [encode_frame(bytes([i]) * (i + 1)) for i in range(40)]
    d = FrameDecoder()
    got = []
    for b in b"".join(frames):
        got += d.feed(bytes([b]))
    assert got == [bytes([i]) * (i + 1) for i in range(40)]


def test_decoder_delivers_several_frames_from_one_chunk():
    d = FrameDecoder()
    assert d.feed(encode_frame(b"a") + encode_frame(b"bc") + encode_frame(b"d")) == [b"a", b"bc", b"d"]


def test_decoder_resyncs_after_garbage():
    d = FrameDecoder()
    assert d.feed(b"garbage" + encode_frame(b"x")) == [b"x"]
    assert d.stats.bytes_discarded == 7


def test_decoder_skips_zero_length_start_and_counts_it():
    d = FrameDecoder()
    assert d.feed(H("99 99 00") + encode_frame(b"ok")) == [b"ok"]
    assert d.stats.bad_length == 1
    assert d.stats.bytes_discarded == 3


def test_decoder_resyncs_after_bad_terminator_one_byte_after_the_start():
    # A frame whose tail was lost: its LEN reaches into the next frame, where no 0x55 sits.
    d = FrameDecoder()
    damaged = H("99 99 06 00 04 01")                  # promised 6 bytes, 3 arrived
    good = encode_frame(b"\x00\x04\x02\x03\x04\x05\x06\x07")
    assert d.feed(damaged + good) == [b"\x00\x04\x02\x03\x04\x05\x06\x07"]
    assert d.stats.bad_terminator == 1
    assert d.stats.bytes_discarded == len(damaged)


def test_decoder_restarts_hunt_at_second_sync_byte():
    # 99 99 99 03 ...: the start at 0 reads LEN 0x99 and fails; the real frame starts at 1.
    d = FrameDecoder()
    stream = H("99") + encode_frame(b"abc") + encode_frame(b"\x01" * 160)
    assert d.feed(stream) == [b"abc", b"\x01" * 160]
    assert d.stats.bad_terminator == 1 and d.stats.bytes_discarded == 1


def test_decoder_keeps_trailing_sync_byte_split_across_chunks():
    d = FrameDecoder()
    frame = encode_frame(b"zz")
    assert d.feed(b"junk" + frame[:1]) == []
    assert d.buffered == 1
    assert d.feed(frame[1:]) == [b"zz"]
    assert d.stats.bytes_discarded == 4


def test_decoder_discards_garbage_without_sync_immediately():
    d = FrameDecoder()
    d.feed(bytes(range(0x99)) * 10)
    assert d.buffered == 0 and d.stats.bytes_discarded == 0x99 * 10


def test_decoder_payload_may_contain_sync_and_end_bytes():
    payload = H("99 99 55 99 55 99")
    d = FrameDecoder()
    assert d.feed(encode_frame(payload) + encode_frame(payload)) == [payload, payload]


def test_decoder_flush_gives_up_incomplete_start_and_frees_frames_behind_it():
    # A start with a large LEN (its tail was lost) holds back the frame behind it until flushed.
    d = FrameDecoder()
    assert d.feed(H("99 99 F0 00 04") + encode_frame(b"late")) == []
    assert d.flush() == [b"late"]
    assert d.stats.stalled == 1 and d.buffered == 0
    assert d.stats.bytes_discarded == 5


def test_decoder_flush_empties_the_buffer_even_of_a_lone_sync_byte():
    d = FrameDecoder()
    d.feed(encode_frame(b"a") + H("99"))
    assert d.buffered == 1
    assert d.flush() == [] and d.buffered == 0 and d.stats.bytes_discarded == 1


def test_decoder_flush_leaves_nothing_to_give_up_when_idle():
    d = FrameDecoder()
    d.feed(encode_frame(b"a"))
    assert d.flush() == [] and d.stats.stalled == 0


def test_decoder_reset_counts_what_it_throws_away():
    d = FrameDecoder()
    d.feed(H("99 99 10 01 02"))
    d.reset()
    assert d.buffered == 0 and d.stats.reset == 1 and d.stats.bytes_discarded == 5
    assert d.feed(encode_frame(b"new")) == [b"new"]


def test_decoder_never_holds_more_than_one_incomplete_frame():
    d = FrameDecoder()
    d.feed(H("99 99 FF") + bytes(255))               # a max frame without its terminator
    assert d.buffered == MAX_PENDING
    d.feed(b"\x00")                                   # the wrong terminator: hunt goes on
    assert d.buffered <= MAX_PENDING


# -- decoder: properties ---------------------------------------------------------------------

NO_SYNC = st.binary(min_size=0, max_size=40).map(lambda b: b.replace(b"\x99", b"\x98"))
FAST = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _feed_in_chunks(data, stream: bytes) -> list[bytes]:
    """Feed the stream cut at random points; check the memory bound after every call."""
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=30), label="cuts"))
    d = FrameDecoder()
    out: list[bytes] = []
    prev = 0
    for c in [*cuts, len(stream)]:
        out += d.feed(stream[prev:c])
        assert d.buffered <= MAX_PENDING
        prev = c
    assert d.stats.bytes_received == len(stream)
    # Every received byte is delivered in a frame, discarded, or still buffered.
    delivered = sum(len(p) + 4 for p in out)
    assert delivered + d.stats.bytes_discarded + d.buffered == len(stream)
    return out


class Damaged:
    """A received stream made from an original one by deleting slices and inserting garbage.

    origin[i] is the offset in the original stream of received byte i, or -1 for garbage.
    """

    def __init__(self, data, original: bytes, garbage, delete: bool, avoid: frozenset[int] = frozenset()):
        cuts = sorted(set(data.draw(st.lists(st.integers(0, len(original)), max_size=16), label="slices")) - avoid)
        bounds = [0, *cuts, len(original)]
        received = bytearray()
        origin: list[int] = []
        for a, b in zip(bounds, bounds[1:]):
            if data.draw(st.integers(0, 3), label="insert?") == 0:
                g = data.draw(garbage, label="garbage")
                received += g
                origin += [-1] * len(g)
            if delete and data.draw(st.integers(0, 3), label="delete?") == 0:
                continue
            received += original[a:b]
            origin += range(a, b)
        self.stream = bytes(received)
        self.origin = origin
        self.where = {o: i for i, o in enumerate(origin) if o >= 0}

    def clean(self, a: int, b: int) -> bool:
        """Received bytes a..b (inclusive) are one unbroken slice of the original stream."""
        o = self.origin
        return all(o[j] >= 0 for j in range(a, b + 1)) and all(o[j] == o[j - 1] + 1 for j in range(a + 1, b + 1))

    def received_span(self, start: int, end: int) -> tuple[int, int] | None:
        """Where original bytes start..end sit in the received stream, if they arrived intact."""
        r = self.where.get(start)
        if r is None or r + (end - start) >= len(self.origin) or not self.clean(r, r + end - start):
            return None
        return r, r + end - start


def _frames(payloads: list[bytes]) -> tuple[bytes, list[tuple[int, int]]]:
    spans, stream, pos = [], bytearray(), 0
    for p in payloads:
        f = encode_frame(p)
        spans.append((pos, pos + len(f) - 1))
        stream += f
        pos += len(f)
    return bytes(stream), spans


@FAST
@given(st.lists(st.binary(min_size=1, max_size=255), max_size=12), st.data())
def test_clean_stream_cut_anywhere_delivers_every_frame_once_in_order(payloads, data):
    stream, _ = _frames(payloads)
    assert _feed_in_chunks(data, stream) == payloads


@FAST
@given(st.lists(st.tuples(NO_SYNC, st.binary(min_size=1, max_size=255)), max_size=12), NO_SYNC, st.data())
def test_garbage_without_sync_between_frames_loses_no_frame(items, tail, data):
    # Arbitrary payloads (they may contain 99 99 and 55); garbage between frames has no 0x99.
    stream = b"".join(g + encode_frame(p) for g, p in items) + tail
    assert _feed_in_chunks(data, stream) == [p for _, p in items]


@FAST
@given(st.binary(max_size=1500), st.data())
def test_decoder_output_does_not_depend_on_chunking_for_any_bytes(stream, data):
    assert _feed_in_chunks(data, stream) == [p for _, _, p in reference_frames(stream)]


@FAST
@given(st.lists(st.binary(min_size=1, max_size=255), max_size=10), st.data())
def test_damaged_stream_matches_spec_model(payloads, data):
    # Arbitrary payloads, arbitrary garbage, arbitrary lost slices: the decoder does exactly what
    # section 2 says (the reference model), whatever the chunking.
    original, _ = _frames(payloads)
    dmg = Damaged(data, original, st.binary(max_size=40), delete=True)
    assert _feed_in_chunks(data, dmg.stream) == [p for _, _, p in reference_frames(dmg.stream)]


# Payloads without 0x99 and LEN != 0x99: then the only 0x99 0x99 in an undamaged stretch are real
# frame starts, which lets us say exactly which frames must survive damage.
SAFE_PAYLOAD = (st.binary(min_size=1, max_size=255)
                .map(lambda b: b.replace(b"\x99", b"\x98"))
                .filter(lambda b: len(b) != 0x99))


@FAST
@given(st.lists(SAFE_PAYLOAD, max_size=10), st.data())
def test_damage_never_hides_a_frame_with_clean_bytes_before_it(payloads, data):
    """Lost slices and arbitrary garbage (which may hold 0x99 and 0x55):

    - every delivered frame is an original frame that arrived intact, or spans a damaged spot
      (without a checksum a damaged start can be completed by chance; it can never be clean);
    - every intact frame preceded by 258 undamaged bytes (or undamaged since the stream began)
      is delivered exactly once: damage before it cannot reach it;
    - original frames are delivered in order, none twice.
    """
    original, spans = _frames(payloads)
    dmg = Damaged(data, original, st.binary(max_size=40), delete=True)
    out = _feed_in_chunks(data, dmg.stream)
    ref = reference_frames(dmg.stream)
    assert out == [p for _, _, p in ref]

    intact = {}
    for k, (s, e) in enumerate(spans):
        rs = dmg.received_span(s, e)
        if rs is not None:
            intact[rs] = k
    delivered_originals = []
    for start, end, _ in ref:
        if (start, end) in intact:
            delivered_originals.append(intact[(start, end)])
        else:
            assert not dmg.clean(start, end), "an undamaged stretch produced a frame that was never sent"
    assert delivered_originals == sorted(set(delivered_originals))
    for (r, e), k in intact.items():
        if dmg.clean(max(0, r - 258), e):
            assert k in delivered_originals, f"intact frame {k} at {r} lost"


NO_SYNC_NO_END = st.binary(max_size=40).map(lambda b: b.replace(b"\x99", b"\x98").replace(b"\x55", b"\x54"))
STRICT_PAYLOAD = (st.binary(min_size=1, max_size=255)
                  .map(lambda b: b.replace(b"\x99", b"\x98").replace(b"\x55", b"\x54"))
                  .filter(lambda b: len(b) not in (0x55, 0x99)))


@FAST
@given(st.lists(STRICT_PAYLOAD, max_size=10), st.data())
def test_inserted_garbage_damages_only_the_frame_it_lands_in(payloads, data):
    # When neither garbage nor payloads contain 0x99 or 0x55 (nor LEN), garbage inserted anywhere
    # inside a frame can never complete a false frame: exactly the intact frames arrive. The one
    # exception is excluded: a garbage byte right after 0x99 0x99 becomes the LEN, which can point
    # exactly at a later 0x55 (the format has no checksum to catch that).
    original, spans = _frames(payloads)
    after_sync = frozenset(s + 2 for s, _ in spans)
    dmg = Damaged(data, original, NO_SYNC_NO_END, delete=False, avoid=after_sync)
    out = _feed_in_chunks(data, dmg.stream)
    expected = [payloads[k] for k, (s, e) in enumerate(spans) if dmg.received_span(s, e) is not None]
    assert out == expected


# -- the short frame of envelope links (docs/wire-format.md section 14.1) ----------------------

def _envelopes(n: int) -> list[bytes]:
    from uwgen.runtime.wire.envelope import Envelope, Message
    return [Envelope(1, i, (Message(0, 4, bytes((i % 256,)) * (1 + i % 40)),)).encode()
            for i in range(n)]


def _short_decoder():
    from uwgen.runtime.link.packets import envelope_check
    from uwgen.runtime.wire.framing import ShortFrameDecoder
    return ShortFrameDecoder(envelope_check)


def test_a_short_frame_is_one_length_byte_and_the_envelope():
    from uwgen.runtime.wire.framing import FrameError, encode_short_frame
    assert encode_short_frame(bytes.fromhex("80 10 05 04 7D 23")) == bytes.fromhex(
        "06 80 10 05 04 7D 23")
    with pytest.raises(FrameError):
        encode_short_frame(bytes.fromhex("00 04 F5"))     # not an envelope: no version bits 100
    with pytest.raises(FrameError):
        encode_short_frame(bytes.fromhex("60 10 05 04"))  # wire format 3's P: not this build's


def test_the_short_frame_knows_the_version_bits_the_envelope_speaks():
    from uwgen.runtime.wire import envelope, framing
    assert (framing.ENVELOPE_MASK, framing.ENVELOPE_BITS) == (envelope.VERSION_MASK,
                                                              envelope.VERSION_BITS)


def test_a_short_frame_that_also_looks_like_a_long_one_is_read_as_the_envelope():
    # LEN 0x99 and P 0x99 (version 4, S, K, C): a 153-byte sealed envelope with a sync part
    # and a control part; its W high byte, read as a long frame's LEN (16), points at the
    # 0x55 that is its body's third byte.
    from uwgen.runtime.wire.envelope import Envelope, Message, Sync
    from uwgen.runtime.wire.framing import encode_short_frame
    body = bytearray(range(0x99 - 3 - 10 - 2 - 1 - 8))      # P W, K, C, H, tag
    body[2] = 0x55
    e = Envelope(1, 0x0A0, (Message(0, 4, bytes(body)),), sync=Sync(bytes(6), 0),
                 control=b"\x00", tag=bytes(8))
    frame = encode_short_frame(e.encode())
    assert frame[:3] == bytes.fromhex("99 99 10") and frame[3 + 0x10] == 0x55
    d = _short_decoder()
    assert d.feed(frame + encode_short_frame(_envelopes(1)[0])) == [frame[1:], _envelopes(1)[0]]


def test_short_frames_come_out_whole_however_the_stream_is_cut():
    from uwgen.runtime.wire.framing import encode_short_frame
    payloads = _envelopes(60)
    stream = b"".join(encode_short_frame(p) for p in payloads)
    for step in (1, 3, 7, 64):
        d = _short_decoder()
        out = [f for i in range(0, len(stream), step) for f in d.feed(stream[i:i + step])]
        assert out == payloads


def test_after_a_slice_lost_mid_frame_the_short_decoder_finds_the_next_frames():
    from uwgen.runtime.wire.framing import encode_short_frame
    payloads = _envelopes(40)
    frames = [encode_short_frame(p) for p in payloads]
    for cut in range(1, len(frames[10])):
        stream = b"".join(frames[:10]) + frames[10][cut:] + b"".join(frames[11:])
        d = _short_decoder()
        out = d.feed(stream) + d.flush()
        assert out[:10] == payloads[:10]
        # what follows the damaged frame is found again within a few frames, in order
        tail = out[10:]
        assert tail and tail == payloads[40 - len(tail):] and len(tail) >= 40 - 11 - 3


def test_a_long_frame_reaches_the_envelope_layer_to_be_counted():
    d = _short_decoder()
    assert d.feed(encode_frame(bytes.fromhex("40 10 05 04 7D 23"))) == [
        bytes.fromhex("40 10 05 04 7D 23")]
