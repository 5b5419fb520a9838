"""The link's MAC as the connection and the packer see it, and mode `none` (docs/seams.md
section 7; the modes: uwgen.runtime.link.mac).

Sans-IO: every call carries `now` (the link's clock). The connection writes when both its
`Pacer` (DESERT's one packet per period) and the `Mac` allow it: `next_write_at(now)`
(-inf: now, inf: not until something is heard), then `wrote(now, nbytes)` for each write,
or `abandoned()` when the packet built came too `late` to be written; the Link tells it
every message offered (`offered`). The packer asks `hooks()` for the C items of each packet
(`control`), for an empty packet that must leave (`ack_only`: a grant or an end of turn)
and tells it every admitted envelope (`received` -> `heard`). `turn_gap()` is the longest a
reply waits for the peer's turn: delivery's retransmission timer starts no lower than a
round trip plus it.
"""
from __future__ import annotations

import math
from collections.abc import Callable

from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.wire.codec import KIND_RESPONSE

INF = math.inf
ANSWER = bytes([KIND_RESPONSE])      # an offered payload's first byte: its kind (wire format 1)


class Mac:
    """Mode `none`: DESERT's MAC decides; this side writes whenever its pacer allows."""

    mode = "none"
    overhead = 0                         # most bytes the MAC adds to a packet (C part included)
    burst = 0.0                          # s between write windows: rate limits hold over it
    late_collides = False                # a packet written after its moment meets another turn

    def __init__(self):
        self.backlog: Callable[[float], bool] = lambda now: False   # set by the Link
        self.carries = False             # the packet being built carries messages
        self.offered_at = -INF           # when the link was last offered a message (`offered`)
        self.answered_at = -INF          # ... an answer (a response, a goal's answer or result)

    def next_write_at(self, now: float) -> float:
        return -INF

    def offered(self, now: float, payload: bytes) -> None:
        """The link took `payload` to send (the Link tells every offer): a stream offered at
        the link's pace keeps a turns leader's turn, an answer ends a follower's wait for it."""
        self.offered_at = now
        if payload[:1] == ANSWER:
            self.answered_at = now

    def wrote(self, now: float, nbytes: int) -> None:
        pass

    def arrived(self, nbytes: int | None, now: float) -> None:
        """A packet of `nbytes` (None: not known) arrived; `heard` follows (wire format 2)."""

    def heard(self, sender: int, control: bytes, now: float) -> None:
        pass

    def parts(self, now: float) -> bytes:
        return b""

    def must_send(self, now: float) -> bool:
        return False

    def next_time(self, now: float) -> float | None:
        return None

    def late(self, now: float) -> bool:
        """Whether the packet just built may no longer be written at `now`: its moment passed
        while it was built (a stalled thread) and, under a MAC whose late write meets another
        side's turn (`late_collides`: turns, a grant or an end), it would collide. The
        connection then drops it (`abandoned`): delivery takes it as lost, the peer's report
        names it."""
        return self.late_collides and self.next_write_at(now) > now

    def abandoned(self) -> None:
        """The packet built last was not written (`late`): what it would have ended (a grant,
        an end) is not (`late` already moved the turn on)."""

    def turn_gap(self) -> float:
        return 0.0

    def round(self) -> float:
        """A round as this side lives it, from one of its own turns or slots to the next:
        what a repair that waits for the peer's report and then its own turn takes. Under
        turns it is measured (turn_timing.Rounds; `turn_gap()`, a bound, until then); a
        TDMA frame is fixed. The bridge counts a command's rounds left with it (its urgency:
        uwgen.bridge.wiring)."""
        return self.turn_gap()

    def next_turn(self, now: float) -> float:
        """When a message offered at `now` can next leave: `now` while this side holds its
        turn, or without turns; under turns the likely start of its next own turn (a round
        after its last began). The bridge counts a command's rounds left from then."""
        return now

    def own_span(self) -> float:
        """The longest this side's own turn or slot lasts (its packets follow one another
        within it): a command's copy in spare room goes no later (delivery's echoes). 0: no
        turn (DESERT's MAC decides when a packet leaves)."""
        return 0.0

    def settled_by(self, sender: int, now: float) -> float | None:
        """Until when this side's writes had all reached `sender` or been lost before the
        packet heard from it now was built (None: the MAC cannot say). Delivery takes a
        report in that packet as naming all of them (a packet it does not name was lost)."""
        return None

    def reports_twice(self) -> bool:
        """Whether a report that tells a loss also rides this side's next packet (delivery's
        `AckPolicy.twice`): only where that packet leaves anyway within the same turn."""
        return False

    def unheard(self, sender: int) -> float | None:
        """When this side last gave up waiting for the rest of `sender`'s turn (None: never,
        or the MAC has no turns): the turn's last packets were lost. Delivery then reports on
        `sender` in its next packet, news or not: under `settled_by` that report names them
        lost, and their messages go again a round sooner (docs/wire-format.md section 15.2)."""
        return None

    def stats(self) -> dict:
        return {"mode": self.mode}

    def hooks(self) -> PacketHooks | None:
        if self.mode != "turns":
            return None             # nothing to add to packets: the connection asks it directly
        return PacketHooks(parts=self._part, received=self._received, overhead=self.overhead,
                           ack_only=self.must_send, next_time=self.next_time,
                           carrying=self._carrying)

    def _carrying(self, picked: list, now: float, fresh: bool | None = None) -> None:
        # copies in spare room never keep a turn going: only fresh messages count
        self.carries = bool(picked) if fresh is None else fresh

    def _part(self, now: float) -> dict:
        control = self.parts(now)
        return {"control": control} if control else {}

    def _received(self, envelope, now: float) -> None:
        self.heard(envelope.sender, envelope.control or b"", now)
