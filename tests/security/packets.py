"""Per-packet seal helpers: a surface/vehicle pair of PacketSeals (manual clocks), and packets
built and opened as a link builds and opens them (runtime.packets.Packer / Unpacker)."""
from __future__ import annotations

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.link.packets import PACKET_COUNTERS, Packer, Unpacker
from uwgen.runtime.stats import Counters
from uwgen.security.packet_seal import PacketSeal

from .helpers import KEY, SURFACE, VEHICLE, WALL0, config

FRAGMENT_ID = 250


class Queue:
    """The scheduler side of a Packer: hands out queued (key, payload) pairs while they fit."""

    def __init__(self):
        self.items: list[tuple[int, bytes]] = []

    def next_payload(self, now: float, budget: int | None = None, exclude=None, *, fill=False,
                     **_):
        if not self.items:
            return None
        if budget is not None and env.v1_message_size(self.items[0][1]) + 1 > budget:
            return None
        return self.items.pop(0)


class Side:
    """One side's seal with the packer and unpacker of its link."""

    def __init__(self, seal: PacketSeal, sender: int, max_read_length: int = 255):
        self.seal, self.queue = seal, Queue()
        self.packer = Packer(self.queue, sender=sender, max_read_length=max_read_length,
                             hooks=seal.hooks(), counters=Counters(PACKET_COUNTERS))
        self.unpacker = Unpacker(seal.hooks(), counters=Counters(PACKET_COUNTERS))

    def send(self, *payloads: bytes, now: float = 0.0) -> bytes:
        """One packet carrying `payloads` (wire format 1 payloads), sealed now."""
        self.queue.items += [(env.from_v1(p).id, p) for p in payloads]
        data = self.packer.next_packet(now)
        assert data is not None and not self.queue.items, "the payloads did not fit one packet"
        return data

    def receive(self, data: bytes, now: float = 0.0) -> list[bytes]:
        """The payloads delivered from one packet ([] when dropped)."""
        return self.unpacker.feed(data, now)

    def stats(self) -> dict:
        return self.seal.stats()


def surface(folder=None, key=KEY, clock=None, wall=None, tag_bytes=8, **kw) -> Side:
    seal = PacketSeal.for_key(key, config(SURFACE, VEHICLE, "vehicle", tag_bytes=tag_bytes),
                              folder / "surface.lock" if folder is not None else None,
                              clock=clock or ManualClock(), wall=wall or ManualClock(WALL0),
                              name="surface", fragment_id=FRAGMENT_ID, **kw)
    return Side(seal, SURFACE)


def vehicle(folder=None, key=KEY, clock=None, wall=None, tag_bytes=8, **kw) -> Side:
    seal = PacketSeal.for_key(key, config(VEHICLE, SURFACE, "surface", tag_bytes=tag_bytes),
                              folder / "vehicle.lock" if folder is not None else None,
                              clock=clock or ManualClock(), wall=wall or ManualClock(WALL0),
                              name="vehicle", fragment_id=FRAGMENT_ID, **kw)
    return Side(seal, VEHICLE)
