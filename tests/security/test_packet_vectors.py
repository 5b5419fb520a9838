"""The worked bytes of docs/wire-format.md sections 12.2 and 12.3 (the per-packet seal of wire
format 2 and its sync request), recomputed byte for byte, and read back."""
from __future__ import annotations

import pytest

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.wire.codec import pack_items
from uwgen.security import control, packetwire, wire
from uwgen.security.keys import working_key

from .docvectors import DOC, vectors

MASTER = bytes(range(32))
EPOCH = bytes.fromhex("A0A1A2A3A4A5")
VEHICLE_EPOCH = bytes.fromhex("B0B1B2B3B4B5")
TIME = 0x123456
NUMBER = 0x1040
FINGERPRINT = bytes.fromhex("0123456789ABCDEF")
MODES = {4: "encrypt", 20: "sign", 7: "sign"}
TWIST = pack_items([0, 4, 0.5, 0.0, 0.0, 0.0, 0.0, -0.25])
REQUEST = pack_items([2, 20, 7, True])
LOG = pack_items([0, 7, "hi"])


def encrypts(m: env.Message) -> bool:
    return MODES.get(m.id) == "encrypt"


def fingerprint(ident: int) -> bytes:
    return FINGERPRINT if ident == 20 else b""


def documented() -> dict[str, bytes]:
    text = DOC.read_text(encoding="utf-8")
    section = text[text.index("### 12.2"):text.index("## 13.")]
    return vectors(section)


@pytest.fixture(scope="module")
def doc():
    return documented()


def sync_envelope() -> env.Envelope:
    return env.Envelope(1, NUMBER % env.NUMBER_MOD, (env.from_v1(TWIST), env.from_v1(REQUEST)),
                        sync=env.Sync(EPOCH, NUMBER >> 12), time=TIME)


def computed() -> dict[str, bytes]:
    aead = wire.new_aead(working_key(MASTER, "demo", 1, EPOCH))
    e = sync_envelope()
    head = env.Envelope(1, e.number, sync=e.sync, time=TIME, tag=bytes(8)).encode_head()
    ordinary = env.Envelope(1, (NUMBER + 1) % env.NUMBER_MOD, (env.from_v1(TWIST),))
    ask = env.Envelope(2, 0, (env.from_v1(LOG),), sync=env.Sync(VEHICLE_EPOCH, 0), time=TIME,
                       control=control.sync_request(1))
    return {
        "packet_nonce": wire.nonce(1, NUMBER),
        "packet_plain": e.encode(),
        "packet_aad": packetwire.aad(head, e.messages, [True, False], fingerprint),
        "packet_sync": packetwire.seal(aead, e, NUMBER, encrypts, fingerprint),
        "packet": packetwire.seal(aead, ordinary, NUMBER + 1, encrypts, fingerprint),
        "packet_tag4": packetwire.seal(wire.new_aead(working_key(MASTER, "demo", 1, EPOCH), 4),
                                       ordinary, NUMBER + 1, encrypts, fingerprint),
        "ask": packetwire.seal(wire.new_aead(working_key(MASTER, "demo", 2, VEHICLE_EPOCH)), ask, 0,
                               encrypts, fingerprint),
    }


def test_every_documented_vector_is_recomputed_byte_for_byte(doc):
    mine = computed()
    assert set(doc) == set(mine)
    for name, value in mine.items():
        assert doc[name].hex(" ") == value.hex(" "), name


def test_documented_packets_open_to_their_messages(doc):
    aead = wire.new_aead(working_key(MASTER, "demo", 1, EPOCH))
    sealed = env.decode(doc["packet_sync"])
    assert (sealed.sync.high << 12) | sealed.number == NUMBER
    opened = packetwire.open_envelope(aead, sealed, NUMBER, encrypts, fingerprint)
    assert [env.to_v1(m) for m in opened.messages] == [TWIST, REQUEST]
    assert TWIST[2:] not in doc["packet_sync"] and REQUEST[2:] in doc["packet_sync"]
    later = env.decode(doc["packet"])
    assert [env.to_v1(m) for m in packetwire.open_envelope(aead, later, NUMBER + 1, encrypts,
                                                           fingerprint).messages] == [TWIST]
    asked = env.decode(doc["ask"])
    assert control.items(asked.control) == [control.Item(control.SYNC_REQUEST, 1)]


def test_another_fingerprint_mode_or_number_fails_the_tag(doc):
    aead = wire.new_aead(working_key(MASTER, "demo", 1, EPOCH))
    sealed = env.decode(doc["packet_sync"])
    assert packetwire.open_envelope(aead, sealed, NUMBER, encrypts, lambda i: b"") is None
    assert packetwire.open_envelope(aead, sealed, NUMBER, lambda m: False, fingerprint) is None
    assert packetwire.open_envelope(aead, sealed, NUMBER + 4096, encrypts, fingerprint) is None


def test_the_documented_4_byte_tag_opens_only_at_its_length(doc):
    key = working_key(MASTER, "demo", 1, EPOCH)
    short, full = doc["packet_tag4"], doc["packet"]
    assert len(short) == len(full) - 4 and short[:-4] == full[:-8]   # same ciphertext, another tag
    e = env.decode(short, 4)
    opened = packetwire.open_envelope(wire.new_aead(key, 4), e, NUMBER + 1, encrypts, fingerprint)
    assert [env.to_v1(m) for m in opened.messages] == [TWIST]
    assert packetwire.open_envelope(wire.new_aead(key, 8), env.decode(short, 8), NUMBER + 1,
                                    encrypts, fingerprint) is None
    assert packetwire.open_envelope(wire.new_aead(key, 8), e, NUMBER + 1, encrypts, fingerprint) is None
