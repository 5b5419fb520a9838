"""The per-packet tag's length (manifest `security: {tag_bytes}`: 4, 6 or 8): packets seal and
open at each, a changed byte is refused at each (counted `bad_tag`), and two sides built with
different lengths refuse each other clearly (counted `tag_length`, logged once) instead of
dropping every packet as `bad_tag`."""
from __future__ import annotations

import logging

import pytest

from uwgen.runtime.wire import envelope as env
from uwgen.security.errors import SecurityError
from uwgen.security.guard import SYNC_FIRST, GuardConfig, LinkGuard
from uwgen.security.packet_seal import PacketSeal, max_overhead

from .helpers import KEY, log_line, request, twist
from .packets import surface, vehicle

LENGTHS = (4, 6, 8)


def unsealed_size(*payloads: bytes) -> int:
    return len(env.Envelope(1, 0, tuple(env.from_v1(p) for p in payloads)).encode())


@pytest.mark.parametrize("n", LENGTHS)
def test_packets_seal_and_open_at_each_length(n):
    s, v = surface(tag_bytes=n), vehicle(tag_bytes=n)
    payloads = (twist(0.5), log_line("readable"), request(7))
    for i in range(SYNC_FIRST + 2):                  # sync packets, then ordinary ones
        data = s.send(*payloads)
        assert v.receive(data) == list(payloads)
        sync = i < SYNC_FIRST
        assert len(data) == unsealed_size(*payloads) + n + (13 if sync else 0)
        assert env.decode(data, n).tag == data[-n:]
    assert twist(0.5)[2:] not in data                # encrypted at every length
    assert v.stats()["verified"] == SYNC_FIRST + 2 and v.stats()["dropped"] == 0
    assert s.seal.hooks().overhead == max_overhead(n) == n + 13 + 2


@pytest.mark.parametrize("n", LENGTHS)
def test_a_changed_byte_is_refused_at_each_length(n):
    s, v = surface(tag_bytes=n), vehicle(tag_bytes=n)
    assert v.receive(s.send(twist(1.0))) == [twist(1.0)]
    data = s.send(twist(2.0), log_line("x"))
    for i in range(len(data)):
        for flip in (0x01, 0x80):
            forged = bytearray(data)
            forged[i] ^= flip
            assert v.receive(bytes(forged)) == [], (n, i, flip)
    before = v.stats()["bad_tag"]
    for i in (len(data) - 1, len(data) - n, 5):      # the tag's last and first byte, a body byte
        forged = bytearray(data)
        forged[i] ^= 0x01
        assert v.receive(bytes(forged)) == []
    assert v.stats()["bad_tag"] == before + 3
    assert v.stats()["tag_length"] == 0              # a forgery is not taken for another length
    assert v.receive(data) == [twist(2.0), log_line("x")]


@pytest.mark.parametrize("sent,kept", [(4, 8), (8, 4), (6, 4), (8, 6)])
def test_sides_with_different_lengths_refuse_each_other_clearly(sent, kept, caplog):
    s, v = surface(tag_bytes=sent), vehicle(tag_bytes=kept)
    with caplog.at_level(logging.ERROR, logger="uwgen.security"):
        for i in range(SYNC_FIRST + 3):
            assert v.receive(s.send(twist(float(i)))) == []
    stats = v.stats()
    assert stats["tag_length"] == SYNC_FIRST         # each sync packet, named for what it is
    assert stats["bad_tag"] == 0 and stats["verified"] == 0
    assert stats["unsynced"] == 3                    # the others: no epoch of that sender taken
    said = [r.getMessage() for r in caplog.records if "-byte tags" in r.getMessage()]
    assert len(said) == 1                            # once per peer
    assert f"with {sent}-byte tags, this side expects {kept} bytes" in said[0]
    assert "sender 1 (surface)" in said[0] and "security: tag_bytes" in said[0]


def test_a_forged_sync_packet_stays_a_bad_tag():
    s, v = surface(tag_bytes=8), vehicle(tag_bytes=8)
    data = bytearray(s.send(twist(1.0)))             # a sync packet (the first of the epoch)
    assert env.decode(bytes(data)).sync is not None
    data[-1] ^= 0x40
    assert v.receive(bytes(data)) == []
    assert v.stats()["bad_tag"] == 1 and v.stats()["tag_length"] == 0


def test_the_decoder_is_told_the_length_and_refuses_others():
    s = surface(tag_bytes=4)
    data = s.send(twist(1.0))
    assert len(env.decode(data, 4).tag) == 4
    assert env.decode(data, 8).tag == data[-8:]      # other lengths split elsewhere: no guessing
    with pytest.raises(ValueError, match="4, 6 or 8 bytes, not 5"):
        env.decode(data, 5)
    with pytest.raises(env.EnvelopeError, match="tag must be 4, 6 or 8 bytes, got 5"):
        env.Envelope(1, 0, tag=bytes(5)).encode()


def test_a_seal_refuses_a_length_ccm_is_not_given_here():
    config = GuardConfig("demo", 1, {2: "vehicle"}, {4: "encrypt"}, tag_bytes=10)
    with pytest.raises(SecurityError, match="4, 6 or 8 are allowed"):
        PacketSeal(KEY, config)


def test_the_per_payload_seal_keeps_its_8_byte_tag():
    config = GuardConfig("demo", 1, {2: "vehicle"}, {4: "encrypt"}, tag_bytes=4)
    with pytest.raises(SecurityError, match="wire format 1 has an 8-byte tag, not 4"):
        LinkGuard(KEY, config)
