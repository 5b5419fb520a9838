"""The worked bytes of docs/wire-format.md section 12, recomputed byte for byte, and read back."""
from __future__ import annotations

import pytest

from uwgen.runtime.wire.codec import pack_items
from uwgen.security import wire
from uwgen.security.keys import working_key
from uwgen.security.window import ReplayWindow

from .docvectors import DOC, vectors

MASTER = bytes(range(32))
SEQ = 0x12345
EPOCH = bytes.fromhex("A0A1A2A3A4A5")
TIME = 0x123456
SYNC = wire.Sync(EPOCH, TIME)
FINGERPRINT = bytes.fromhex("0123456789ABCDEF")


def documented() -> dict[str, bytes]:
    text = DOC.read_text(encoding="utf-8")
    section = text[text.index("## 12. Security"):]
    section = section[:section.index("\n## ", 10)] if "\n## " in section[10:] else section
    section = section[:section.index("### 12.2")]      # the per-packet seal: test_packet_vectors.py
    return vectors(section)


@pytest.fixture(scope="module")
def doc():
    return documented()


def computed() -> dict[str, bytes]:
    key = working_key(MASTER, "demo", 1, EPOCH)
    aead = wire.new_aead(key)
    twist = pack_items([0, 4, 0.5, 0.0, 0.0, 0.0, 0.0, -0.25])
    req = pack_items([2, 20, 7, True])
    return {
        "working_key": key,
        "nonce": wire.nonce(1, SEQ),
        "word": wire.word(1, SEQ, None),
        "sync_word": wire.word(1, SEQ, SYNC),
        "payload": twist,
        "aad_encrypt": wire.aad("encrypt", 1, b"", twist[:2], wire.word(1, SEQ, None)),
        "encrypt": wire.seal(aead, "encrypt", 1, SEQ, twist),
        "encrypt_sync": wire.seal(aead, "encrypt", 1, SEQ, twist, sync=SYNC),
        "sign": wire.seal(aead, "sign", 1, SEQ, twist),
        "request": req,
        "aad_request": wire.aad("sign", 1, FINGERPRINT, req[:3], wire.word(1, SEQ + 1, None)),
        "request_sign": wire.seal(aead, "sign", 1, SEQ + 1, req, FINGERPRINT),
    }


def test_every_documented_vector_is_recomputed_byte_for_byte(doc):
    mine = computed()
    assert set(doc) == set(mine)
    for name, value in mine.items():
        assert doc[name].hex(" ") == value.hex(" "), name


def test_the_documented_payload_is_what_the_generated_codec_sends(doc, tmp_path):
    from geometry_msgs.msg import Twist

    from uwgen.codegen import generate
    pkg = generate(tmp_path, "uwgen_secvec", names=["geometry_msgs/msg/Twist"])
    msg = Twist()
    msg.linear.x, msg.angular.z = 0.5, -0.25
    assert pkg.codec("geometry_msgs/msg/Twist").encode(msg, [0, 4]) == doc["payload"]   # native


def test_documented_frames_read_back(doc):
    aead = wire.new_aead(working_key(MASTER, "demo", 1, EPOCH))
    window = ReplayWindow(high=SEQ - 1)                 # a receiver that heard the number before
    for name, mode in (("encrypt", "encrypt"), ("sign", "sign"), ("encrypt_sync", "encrypt")):
        p = wire.parse(doc[name])
        seq = p.full_seq() if p.high is not None else window.reconstruct(p.partial)
        assert seq == SEQ and p.sender == 1
        assert wire.open_parsed(aead, mode, p, seq) == doc["payload"]
        assert p.sync in (None, SYNC)
    p = wire.parse(doc["request_sign"])
    assert wire.open_parsed(aead, "sign", p, SEQ + 1, FINGERPRINT) == doc["request"]
    with pytest.raises(wire.InvalidTag):
        wire.open_parsed(aead, "sign", p, SEQ + 1, b"")    # without the fingerprint: refused


def test_a_sync_word_added_to_a_recorded_frame_fails_its_tag(doc):
    # The sync flag, epoch and time are authenticated: a recorded ordinary frame made into a
    # sync frame (so a receiver without state would take it) no longer verifies.
    aead = wire.new_aead(working_key(MASTER, "demo", 1, EPOCH))
    frame = doc["encrypt"]
    forged = frame[:2] + wire.word(1, SEQ, wire.Sync(EPOCH, TIME + 32)) + frame[4:]
    p = wire.parse(forged)
    assert p.full_seq() == SEQ
    with pytest.raises(wire.InvalidTag):
        wire.open_parsed(aead, "encrypt", p, SEQ)
