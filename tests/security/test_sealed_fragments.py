"""Compact fragment messages (wire format 2, H 61) under the per-packet seal: a fragment carries
part of a message whose id it does not name, so a network that encrypts any id must encrypt it.

The tests hold the per-packet seal (uwgen.security.packet_seal) and the fragment messages
together."""
from __future__ import annotations

import pytest

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.fragment import Fragmenter
from uwgen.runtime.wire.reassembly import Reassembler
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, Unpacker
from uwgen.runtime.stats import Counters
from uwgen.security.guard import GuardConfig

packet_seal = pytest.importorskip("uwgen.security.packet_seal")

KEY = bytes(range(32))
WALL0 = 1_790_000_000.0
FID = 250


class Queue:
    """The scheduler side of a Packer: queued (key, payload) pairs while they fit."""

    def __init__(self, items):
        self.items = list(items)

    def next_payload(self, now, budget=None, exclude=None, *, fill=False, cut=None, **_):
        if cut is not None:           # fragments are never cut (wire-format.md section 14.2)
            return None
        if not self.items or (budget is not None and env.v1_message_size(self.items[0][1]) > budget):
            return None
        return self.items.pop(0)


def seal(sender: int, peer: int, modes: dict[int, str]):
    cfg = GuardConfig("n", sender, {peer: f"side{peer}"}, modes)
    return packet_seal.PacketSeal(KEY, cfg, fragment_id=FID, clock=ManualClock(),
                                  wall=ManualClock(WALL0), name=f"side{sender}")


@pytest.mark.parametrize("modes, hidden", [({4: "encrypt"}, True), ({4: "sign"}, False)])
def test_compact_fragments_are_encrypted_when_the_network_encrypts(modes, hidden):
    secret = b"\x00\x04" + b"SECRET-PLAINTEXT" * 20
    fragments = Fragmenter(FID, max_payload=40, compact=True).split(secret)
    a, b = seal(1, 2, modes), seal(2, 1, modes)
    packer = Packer(Queue((4, f) for f in fragments), sender=1, max_read_length=255,
                    hooks=a.hooks(), counters=Counters(PACKET_COUNTERS))
    unpacker = Unpacker(b.hooks(), counters=Counters(PACKET_COUNTERS))
    reassembler = Reassembler(FID, ManualClock())
    whole = []
    while (data := packer.next_packet(0.0)) is not None:
        assert (b"SECRET" not in data) == hidden
        for payload in unpacker.feed(data, 0.0):
            if (m := reassembler.feed(payload)) is not None:
                whole.append(m)
    assert whole == [secret]
