"""The envelope codec of wire format 3: worked bytes, runs, one encoding per envelope, a total
decoder."""
from __future__ import annotations

from dataclasses import replace

import pytest
from hypothesis import given, settings, strategies as st

from uwgen.runtime.wire.envelope import (CUT_HEAD, CUT_TAIL, FRAGMENT, Envelope, EnvelopeError,
                                         Message, Sync, decode, from_v1, ordered, to_v1)


def test_one_message_envelope_is_p_w_h_body():
    env = Envelope(sender=1, number=5, messages=(Message(0, 4, b"\x7d\x23"),))
    assert env.encode() == bytes.fromhex("80 10 05 04 7D 23")


def test_every_message_but_the_last_carries_a_length():
    env = Envelope(sender=2, number=0xABC, messages=(
        Message(0, 4, b"\x7d\x23"), Message(2, 20, b"\x07\xf5"), Message(0, 250, b"\x2a\x00")))
    # 84 02 = topic 4 with length 2; C4 02 = request 20... (kind 01, id 10100) with length 2;
    # 00 FA = topic, id escaped (250), last: no length
    assert env.encode() == bytes.fromhex("80 2A BC 84 02 7D 23 B4 02 07 F5 00 FA 2A 00")
    assert decode(env.encode()) == env


def test_optional_parts_come_in_order_k_t_a_c_and_the_tag_last():
    env = Envelope(sender=3, number=1, messages=(Message(3, 7, b"\x01"),),
                   sync=Sync(bytes.fromhex("A1A2A3A4A5A6"), 2), time=0x123456, ack=b"\xee",
                   control=b"", tag=bytes(range(8)))
    assert env.encode() == bytes.fromhex(
        "9F 30 01 A1 A2 A3 A4 A5 A6 00 00 00 02 12 34 56 01 EE 00 47 01 00 01 02 03 04 05 06 07")
    assert decode(env.encode()) == env
    assert env.head_size() == 3 + 10 + 3 + 2 + 1 + 8


def test_escaped_kind_carries_kind_and_id_bytes():
    env = Envelope(sender=0, number=0, messages=(Message(9, 3, b"x"),))
    assert env.encode() == bytes.fromhex("80 00 00 60 09 03 78")
    assert decode(env.encode()) == env


def test_an_envelope_may_carry_no_message():
    env = Envelope(sender=4, number=9, ack=b"\x01\x02")
    assert decode(env.encode()) == env
    assert env.encode() == bytes.fromhex("82 40 09 02 01 02")


@pytest.mark.parametrize("payload, message", [
    ("00 04 7D 23", Message(0, 4, b"\x7d\x23")),
    ("02 18 FA 07", Message(2, 250, b"\x07")),
    ("03 14 07 F5", Message(3, 20, b"\x07\xf5")),
])
def test_v1_payloads_turn_into_messages_and_back(payload, message):
    assert from_v1(bytes.fromhex(payload)) == message
    assert to_v1(message) == bytes.fromhex(payload)


@pytest.mark.parametrize("payload", ["", "00", "18 04 00", "00 18 04", "00 00 01", "00 19 01 00"])
def test_v1_payload_without_kind_and_id_is_refused(payload):
    with pytest.raises(EnvelopeError):
        from_v1(bytes.fromhex(payload))


@pytest.mark.parametrize("data, why", [
    ("", "at least"),
    ("80 00", "at least"),
    ("00 04 F5", "version bits 0"),
    ("E0 00 00", "version bits 7"),
    ("90 00 00 01 02", "tag"),
    ("88 00 00 01 02 03", "sync"),
    ("84 00 00 01", "time"),
    ("82 00 00 05 01", "acknowledgement"),
    ("81 00 00", "control"),
    ("80 00 00 84 02 01", "does not fit"),
    ("80 00 00 84 01 01", "last message carries a length"),
    ("80 00 00 00 04", "escaped although"),
    ("80 00 00 00", "ends before its id"),
    ("80 00 00 60 00 04", "kind 0 escaped"),
    ("80 00 00 65 05 04", "id bits"),
    ("80 00 00 60 05", "escaped header"),
    ("80 00 00 60 05 00", "id 0"),
    ("80 00 00 84", "before its length"),
])
def test_bad_envelopes_are_refused_with_a_reason(data, why):
    with pytest.raises(EnvelopeError, match=why):
        decode(bytes.fromhex(data))


def test_a_v1_payload_is_recognised_by_its_version_bits():
    with pytest.raises(EnvelopeError) as e:
        decode(bytes.fromhex("00 04 F9 38 00"))
    assert e.value.version == 0


@pytest.mark.parametrize("env", [
    Envelope(sender=16, number=0),
    Envelope(sender=0, number=4096),
    Envelope(sender=0, number=0, time=1 << 24),
    Envelope(sender=0, number=0, tag=b"short"),
    Envelope(sender=0, number=0, ack=bytes(256)),
    Envelope(sender=0, number=0, sync=Sync(b"12345", 0)),
    Envelope(sender=0, number=0, messages=(Message(0, 0, b""),)),
    Envelope(sender=0, number=0, messages=(Message(0, 4, bytes(256)), Message(0, 5, b""))),
    Envelope(sender=0, number=0, messages=(Message(0, 4, bytes(253)),)),
])
def test_encoder_refuses_what_does_not_fit(env):
    with pytest.raises(EnvelopeError):
        env.encode()


messages = st.builds(Message, kind=st.sampled_from([0, 2, 3, 1, 7, 255]),
                     id=st.integers(1, 255), body=st.binary(max_size=20)) \
    | st.builds(Message, kind=st.just(FRAGMENT), id=st.just(0), body=st.binary(max_size=20))
envelopes = st.builds(
    Envelope, sender=st.integers(0, 15), number=st.integers(0, 4095),
    messages=st.lists(messages, max_size=6).map(tuple),
    sync=st.none() | st.builds(Sync, st.binary(min_size=6, max_size=6), st.integers(0, 2**32 - 1)),
    time=st.none() | st.integers(0, 2**24 - 1), ack=st.none() | st.binary(max_size=10),
    control=st.none() | st.binary(max_size=10), tag=st.none() | st.binary(min_size=8, max_size=8))


runs = st.builds(lambda kind, ident, size, bodies: tuple(Message(kind, ident, bytes((b,)) * size)
                                                         for b in bodies),
                 st.sampled_from([0, 2, 7]), st.integers(1, 40), st.integers(0, 5),
                 st.lists(st.integers(0, 255), min_size=1, max_size=6))
grouped = st.builds(
    Envelope, sender=st.integers(0, 15), number=st.integers(0, 4095),
    messages=st.lists(runs | st.tuples(messages), max_size=4).map(lambda r: sum(r, ())),
    tag=st.none() | st.binary(min_size=8, max_size=8))


tails = st.builds(lambda b: Message(CUT_TAIL, 0, b), st.binary(min_size=1, max_size=20))
heads = st.builds(lambda k, i, b: Message(CUT_HEAD | k, i, b), st.sampled_from([0, 2, 3, 7]),
                  st.integers(1, 255), st.binary(min_size=1, max_size=20))
with_cuts = st.builds(                      # cut parts (section 14.2) among the messages
    lambda e, tail, head, at: replace(e, messages=(*e.messages[:at], *tail, *e.messages[at:],
                                                   *head)),
    envelopes, st.lists(tails, max_size=1), st.lists(heads, max_size=1), st.integers(0, 6))


@given(envelopes | grouped | with_cuts)
@settings(max_examples=400)
def test_every_envelope_decodes_to_itself_in_blocks(env):
    got = decode(env.encode())
    assert got == replace(env, messages=ordered(env.messages))
    for key in {(m.kind, m.id) for m in env.messages}:      # each entry's order is kept
        assert [m for m in got.messages if (m.kind, m.id) == key] == \
            [m for m in env.messages if (m.kind, m.id) == key]


def test_three_messages_of_one_id_and_length_share_one_head():
    ms = tuple(Message(0, 4, bytes((i, 0x23, 1, 2))) for i in range(13))
    wire = Envelope(1, 6, ms).encode()
    assert wire[:6] == bytes.fromhex("80 10 06 62 04 0D") and len(wire) == 6 + 52
    assert len(Envelope(1, 6, ms[:9]).encode()) < len(b"".join(m.body for m in ms[:9])) + 3 + 18


def test_the_blocks_follow_first_appearance_and_keep_each_entrys_order():
    a = [Message(0, 4, bytes((i, 0))) for i in range(3)]
    b = Message(2, 20, b"\x07\xf5")
    env = Envelope(0, 1, (a[0], b, a[1], a[2]))
    assert ordered(env.messages) == (a[0], a[1], a[2], b)
    assert env.encode()[3:] == bytes.fromhex("E2 04 03 02 00 00 01 00 02 00 34 07 F5")


@pytest.mark.parametrize("data, why", [
    ("80 00 00 62 04 02 01 02", "at least 3"),                 # a run of 2: singles
    ("80 00 00 62 04 03 01 02 03 04", "do not share out"),
    ("80 00 00 84 01 01 84 01 02 04 03", "one encoding"),    # three singles: a run
    ("80 00 00 E2 04 03 01 01 02 03 04 09", "one encoding"),   # id 4 again after the run
    ("80 00 00 62 E4 03 01 02 03", "not a message's"),
])
def test_runs_out_of_their_one_encoding_are_refused(data, why):
    with pytest.raises(EnvelopeError, match=why):
        decode(bytes.fromhex(data))


def test_a_wire_format_2_envelope_is_recognised_by_its_version_bits():
    with pytest.raises(EnvelopeError) as e:
        decode(bytes.fromhex("40 10 05 04 7D 23"))
    assert e.value.version == 2


@given(st.binary(max_size=300))
@settings(max_examples=1000)
def test_decoder_is_total_and_what_it_accepts_has_one_encoding(data):
    try:
        env = decode(data)
    except EnvelopeError:
        return
    assert env.encode() == data


@given(envelopes | with_cuts, st.data())
@settings(max_examples=300)
def test_a_damaged_envelope_is_refused_or_reencodes_exactly(env, data):
    raw = bytearray(env.encode())
    i = data.draw(st.integers(0, len(raw) - 1))
    raw[i] ^= data.draw(st.integers(1, 255))
    try:
        got = decode(raw)
    except EnvelopeError:
        return
    assert got.encode() == bytes(raw)


@pytest.mark.parametrize("v1, v2", [
    ("00 05 42 7D 23", "00 05 7D 23"),                  # packed Twist: the 42 goes
    ("02 14 19 01 4A 41 80", "02 14 19 01 4A 80"),      # packed request: seq stays, head goes
    ("00 05 58 18" + " 00" * 24, "00 05" + " 00" * 24),
])
def test_packed_payloads_drop_their_byte_string_head_and_get_it_back(v1, v2):
    from uwgen.runtime.wire.envelope import add_packed_head, strip_packed_head
    assert strip_packed_head(bytes.fromhex(v1)) == bytes.fromhex(v2)
    assert add_packed_head(bytes.fromhex(v2)) == bytes.fromhex(v1)


@pytest.mark.parametrize("v1", ["00 05", "00 05 41", "00 05 43 01", "00 05 F5", "02 14"])
def test_a_packed_payload_without_its_byte_string_is_refused(v1):
    from uwgen.runtime.wire.envelope import strip_packed_head
    with pytest.raises(EnvelopeError):
        strip_packed_head(bytes.fromhex(v1))


def test_fragment_messages_are_recognised_in_both_forms():
    from uwgen.runtime.wire.envelope import is_fragment_message
    assert is_fragment_message(Message(FRAGMENT, 0, b"\x01\x00\x02x"), None)
    assert is_fragment_message(Message(0, 250, b"\x01"), 250)
    assert not is_fragment_message(Message(0, 250, b"\x01"), None)
    assert not is_fragment_message(Message(2, 250, b"\x01"), 250)
