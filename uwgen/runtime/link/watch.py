"""What watches a link: its packet observers (`Link.observers`, docs/seams.md section 10) and
what became of the packet being read.

Observers are called on the link's thread with `(time, direction, packet, outcome)`: every
packet written (`tx`, outcome `sent`) and read (`rx`: `delivered N`, `fragment`, `control`
when it carried no message (acknowledgements only), or `dropped REASON`). Empty, they cost
the link one list test a packet; an observer that raises is logged, never stops the link.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

from uwgen.runtime.clock import Clock

log = logging.getLogger("uwgen.link")

Observer = Callable[[float, str, bytes, str], None]   # (time, "tx"|"rx", packet, outcome)
# Packet counters whose increase says why a packet read was refused whole.
UNPACK_DROPS = {"bad_envelopes": "bad_envelope", "version_1": "bad_envelope",
                "version_2": "bad_envelope", "version_3": "bad_envelope",
                "unknown_kind": "bad_envelope", "opened_none": "seal"}


class PacketWatch:
    """The observers, and the outcome of the packet being read: the link sets `drop` (why
    it dropped the packet's payload) and `fragment` (it held a fragment) as it reads."""

    def __init__(self, name: str, clock: Clock, delivered: Callable[[], int],
                 packet_counters: Mapping[str, int]):
        self.name, self.clock = name, clock
        self.observers: list[Observer] = []
        self.drop: str | None = None
        self.fragment = False
        self._delivered = delivered               # the link's count of payloads delivered
        self._packets = packet_counters
        self._before: tuple[int, dict[str, int]] = (0, {})

    def tx(self, source: Callable[..., bytes | None]) -> Callable[..., bytes | None]:
        """`source` (the connection's: now[, room] -> packet or None), telling the observers
        of each packet it gives."""
        def watched(now: float, *args: int) -> bytes | None:
            data = source(now, *args)
            if data is not None and self.observers:
                self._tell(now, "tx", data, "sent")
            return data
        return watched

    def rx(self, on_frame: Callable[[bytes], None], envelopes: bool) -> Callable[[bytes], None]:
        """`on_frame` (the connection's: one packet read), telling the observers what became
        of each (`envelopes`: wire format 2, the unpacker's counters say why one is refused)."""
        def watched(data: bytes) -> None:
            if not self.observers:
                on_frame(data)
                return
            self.reading(envelopes)
            on_frame(data)
            self.read(self.clock.now(), data)
        return watched

    def reading(self, envelopes: bool) -> None:
        """A packet is about to be read (`envelopes`: wire format 2, read by the unpacker)."""
        self.drop, self.fragment = None, False
        self._before = (self._delivered(),
                        {k: self._packets[k] for k in UNPACK_DROPS} if envelopes else {})

    def read(self, now: float, data: bytes) -> None:
        """The packet `reading()` announced has been read: tell the observers what became of it."""
        delivered = self._delivered() - self._before[0]
        why = next((UNPACK_DROPS[k] for k, n in self._before[1].items() if self._packets[k] > n), None)
        if delivered:
            outcome = f"delivered {delivered}"
        elif self.drop is not None or why is not None:
            outcome = f"dropped {self.drop or why}"
        else:
            outcome = "fragment" if self.fragment else "control"
        self._tell(now, "rx", data, outcome)

    def _tell(self, now: float, direction: str, data: bytes, outcome: str) -> None:
        for observer in self.observers:
            try:
                observer(now, direction, data, outcome)
            except Exception:  # noqa: BLE001 - an observer never stops the link
                log.exception("[%s] a packet observer failed", self.name)
