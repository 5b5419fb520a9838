"""load_items reads a CBOR sequence whole, or refuses it: a break code (0xFF) outside an item
never makes it stop early and drop the rest (cbor2.loads would)."""
from __future__ import annotations

import io
import struct

import cbor2
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.runtime.wire.codec import DecodeError, load_items, pack_items


def reference(payload: bytes):
    """A CBORDecoder that says where it stopped, for every payload."""
    try:
        fp = io.BytesIO(b"\x9f" + payload + b"\xff")
        items = cbor2.CBORDecoder(fp).decode()
    except Exception:  # noqa: BLE001 - any refusal
        return "refused"
    return repr(items) if fp.tell() == len(payload) + 2 else "refused"


def outcome(payload: bytes):
    try:
        return repr(load_items(payload))      # repr: NaN is not equal to itself
    except DecodeError:
        return "refused"


F = struct.pack(">f", struct.unpack(">f", b"\x3f\x7f\xff\x00")[0])   # a float32 holding FF


@pytest.mark.parametrize("payload", [
    b"\x00\x04" + b"\xfa" + F,                        # FF inside a float
    b"\x00\x04\x43\x01\xff\x02",                      # FF inside a byte string
    b"\x00\x04\x42\xff\xff",                          # FF FF inside one, at the end
])
def test_items_holding_ff_bytes_decode_whole(payload):
    assert outcome(payload) == reference(payload) != "refused"


@pytest.mark.parametrize("payload", [
    b"\x00\x04\x05\xff\x06",                          # a stray break, then an item
    b"\x00\x04\x05\xff",                              # a stray break at the end
    b"\x00\x04\x05\xff\xff",                          # two of them
    b"\x00\x04\x05\xff\xff\x06",
    b"\x00\x04\xfa" + F + b"\xff\x06",                # FF in a float, then a stray break
    b"\x00\x04\x05\xff\x9f\x01",
])
def test_a_stray_break_code_is_refused_not_cut_at(payload):
    assert outcome(payload) == "refused"
    assert reference(payload) == "refused"


ITEM = st.one_of(st.integers(-2**64 + 1, 2**64 - 1), st.floats(width=32), st.floats(),
                 st.binary(max_size=12), st.text(max_size=6), st.booleans())


@settings(max_examples=300, deadline=None)
@given(st.lists(ITEM, min_size=1, max_size=12))
def test_packed_items_come_back(items):
    assert outcome(pack_items(items)) == repr(items)


@settings(max_examples=600, deadline=None)
@given(st.lists(ITEM, min_size=1, max_size=8), st.lists(st.integers(0, 200), max_size=3),
       st.binary(max_size=4))
def test_any_payload_is_read_as_the_reference_reads_it(items, cuts, tail):
    """Stray breaks (and FF FF pairs) put anywhere, and random tails: the same items or
    the same refusal as the decoder that knows where it stopped."""
    payload = bytearray(pack_items(items))
    for cut in cuts:
        payload.insert(cut % (len(payload) + 1), 0xFF)
    payload = bytes(payload) + tail
    assert outcome(payload) == reference(payload)


@pytest.mark.parametrize("holder", [bytearray, memoryview])
def test_a_stray_break_code_is_refused_in_any_bytes_like_payload(holder):
    assert outcome(holder(b"\x00\x04\x05\xff\x06")) == "refused"
    assert outcome(holder(b"\x00\x04\x43\x01\xff\x02")) == repr([0, 4, b"\x01\xff\x02"])
