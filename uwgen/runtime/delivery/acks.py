"""When acknowledgements leave and what they name (docs/wire-format.md section 15.2).

`AckPolicy` decides, for the packet being built, which peers get a report (a peer waits for
the ack of a reliable message; or, at most every `ack_interval`, news or numbers no report
the peer is known to have received has named yet), how far back
each report's bitmap reaches (to the largest number named by a report the peer is known to
have received: once a packet carrying a report is acknowledged, the numbers it named need
not be named again, as QUIC stops repeating acknowledged ranges), and when a packet must
leave with only the A part. At start, on a link whose sides measure each other's clocks
(wire-format 15.5, the exchange at start), each peer's first `eager` reports (per epoch: again
after a restart), and after them every report until one is known to have arrived (at most
EAGER_MOST), ride every packet leaving, news or not: the peer measures our clock from the
first of them it receives, so lost ones delay it by a packet each, not by the next report's
wait (`ack_interval`, or the peer's next probe and its answer: a TDMA frame each) while the
commands it gets from us are refused `unmeasured`. Under turns, the leader's first packet
after it took a follower's turn back unheard (`unheard`: the turn's end, and maybe the
packets before it, were lost) carries a report on that follower, news or not: the follower
takes it as naming its turn's packets after the report's largest lost (the MAC's
`settled_by`), and sends their answers and results again in its next turn, not a round
later when news would report. The leader (`twice`, the MAC's `reports_twice`) says a report
that tells a loss (a gap, or a turn unheard) once more on its next packet, a notice or the
grant that leaves anyway in the same turn: the follower's repair waits for it, and a lost
report would cost it a round. It keeps its own state and reads the engine
(`uwgen.runtime.delivery.reliable.ReliableLink`); the caller holds the lock and passes `now`.
"""
from __future__ import annotations

import math
from collections.abc import Callable

from uwgen.runtime.delivery.receiving import RECEIVED_WINDOW
from uwgen.runtime.delivery.reliable import MAX_BITMAP, REPORT_KEY, ReliableLink, Sent

BITMAP_ROOM = 2          # bitmap bytes a report may always carry: packets leave room for one
                         # report of 17 numbers (the A part's length, R0-R2, 2 bytes: 6 bytes);
A_ROOM = 1 + 3 + BITMAP_ROOM   # more when the packet being built has room left (`room`)
EPOCHS_KEPT = 64         # peer epochs whose eager reports are counted (the latest kept)
CLOCK_REPLIES = 2        # reports with T answered at a start (the clock exchange)
TIMED_REPORTS = 4        # first packets with an A part that carry T (per peer epoch),
TIMED_REPORT_EVERY = 30.0   # then one every this many seconds: the peer's clock offset
EAGER_MOST = 24          # reports per peer epoch on every packet while none is known arrived
IDLE_REPEATS = 3         # reports sent alone about numbers not confirmed, after the last news


class AckPolicy:
    def __init__(self, engine: ReliableLink, *, ack_delay: float, ack_interval: float,
                 eager: int = 0, unheard: Callable[[int], float | None] | None = None):
        self.engine, self.ack_delay, self.ack_interval = engine, ack_delay, ack_interval
        self.unheard = unheard or (lambda peer: None)   # the MAC's: a peer's turn went unheard
        self.eager = eager                      # reports per peer epoch on every packet (doc)
        self._eager_sent: dict[tuple[int, bytes], int] = {}
        self._confirmed: dict[tuple[int, bytes], int] = {}   # (peer, epoch) -> largest named
        self._reports: list[tuple[int, bytes, int]] = []      # in the packet being built
        self._last_report: dict[int, float] = {}
        self._news: dict[int, float] = {}       # peer -> first packet since our last report
        self._idle: dict[int, int] = {}         # peer -> reports sent alone since its news
        self.final = False                      # a last report on every peer is due (closing)
        # under turns the leader (the MAC's `reports_twice`): a report that tells a loss rides
        # its next packet too, so that it is lost only with both (module doc)
        self.twice = False
        self._again: set[int] = set()           # peers whose loss report goes once more

    def heard(self, peer: int, with_messages: bool, now: float) -> None:
        """A packet of `peer` arrived; an ack-only one asks for nothing (no ping-pong)."""
        if with_messages:
            self._news.setdefault(peer, now)

    def a_part(self, epochs: dict[int, bytes], now: float, room: int = A_ROOM) -> bytes:
        """The A part of the packet being built (b"": none), at most `room` bytes with its
        length byte (at least A_ROOM: what every packet leaves for it)."""
        room = min(max(room, A_ROOM), 1 + 255)
        out = b""
        peers = {p for p, _ in self.engine.receipts}      # the one reported longest ago first
        for peer in sorted(peers, key=lambda p: (self._last_report.get(p, -math.inf), p)):
            r = self.engine._current(peer)
            if r is None or r.largest is None:
                continue
            epoch = epochs.get(peer, b"")
            low = self._confirmed.get((peer, epoch))
            waited, news = self._wanted(peer, r, epoch, now)
            again = peer in self._again
            if not (waited or news or again or self._eager(peer, epoch) or self.final):
                continue
            # a loss told (read before the report clears it): said once more on the next packet
            loss = self.twice and not again and (r.gap or self._unheard(peer))
            if low is None:
                low = min(r.got, default=r.largest)
            fits = max(0, min(MAX_BITMAP, room - 1 - len(out) - 3))
            nbytes = max(0, min(fits, -(-(r.largest - low) // 8)))
            report = self.engine.ack_for(peer, now, nbytes=nbytes)
            if report is not None and 1 + len(out) + len(report) <= room:
                out += report
                if self._eager(peer, epoch):                      # counted until done
                    self._eager_sent[(peer, epoch)] = self._eager_sent.pop((peer, epoch), 0) + 1
                    while len(self._eager_sent) > EPOCHS_KEPT:   # the most recent peer starts
                        del self._eager_sent[next(iter(self._eager_sent))]
                self._reports.append((peer, epoch, r.largest))
                self._last_report[peer] = now
                if loss:
                    self._again.add(peer)
                else:
                    self._again.discard(peer)         # said twice: once more is enough
                if self._news.pop(peer, None) is not None:
                    self._idle[peer] = 0
                elif not waited and not again and low is not None and low < r.largest:
                    # alone again about numbers not confirmed: bounded (nobody acks an
                    # ack-only packet, so its arrival is never confirmed)
                    self._idle[peer] = self._idle.get(peer, 0) + 1
        return out

    def due(self, epochs: dict[int, bytes], now: float) -> bool:
        """Whether `a_part(epochs, now)` would name some peer (without its side effects):
        what the packer leaves room for, asked before a packet's messages are picked."""
        if self.final and self.engine.receipts:
            return True
        for peer in {p for p, _ in self.engine.receipts}:
            r = self.engine._current(peer)
            if r is None or r.largest is None:
                continue
            epoch = epochs.get(peer, b"")
            if any(self._wanted(peer, r, epoch, now)) or self._eager(peer, epoch) \
                    or peer in self._again:
                return True
        return False

    def _wanted(self, peer: int, r, epoch: bytes, now: float) -> tuple[bool, bool]:
        """Why a report on `peer` (its receipts `r`) goes on this packet: (waited, news).
        Waited: the peer waits for an ack of a reliable message, or a gap may hide one (its
        loss is reported now, so the sender re-sends it in its next packet: RFC 5681's
        immediate ack of a segment out of order), or the MAC gave up on the rest of its turn.
        News: packets with messages, or numbers no report the peer received has named yet,
        every ack_interval, until a report naming them is known to have arrived (then the
        peer's ledger has them)."""
        waited = r.eliciting_since is not None or r.gap or self._unheard(peer)
        low = self._confirmed.get((peer, epoch))
        unsettled = peer in self._news or low is None or low < r.largest
        news = unsettled and now - self._last_report.get(peer, -math.inf) >= self.ack_interval
        return waited, news

    def _unheard(self, peer: int) -> bool:
        """The MAC gave up on the rest of the peer's turn since our last report on it."""
        at = self.unheard(peer)
        return at is not None and at > self._last_report.get(peer, -math.inf)

    def _eager(self, peer: int, epoch: bytes) -> bool:
        """A report on the peer's epoch rides every packet: its first `eager`, then while
        none of ours is known to have arrived (the peer has no sample of our clock yet), at
        most EAGER_MOST in all (a peer that never reports on our packets)."""
        if not self.eager:
            return False
        sent = self._eager_sent.get((peer, epoch), 0)
        return sent < self.eager or (peer, epoch) not in self._confirmed and sent < EAGER_MOST

    def eager_any(self, epochs: dict[int, bytes]) -> bool:
        """Some peer's report is eager (`_eager`): the packet being built carries T with it."""
        return any(self._eager(peer, epochs.get(peer, b"")) for peer, _ in self.engine.receipts)

    def rename_epoch(self, peer: int, old: bytes, new: bytes) -> None:
        """The peer's stand-in epoch `old` is `new` (learnt from K): the same start."""
        if (peer, old) in self._confirmed:
            self._confirmed[(peer, new)] = self._confirmed.pop((peer, old))
        if (peer, old) in self._eager_sent:
            self._eager_sent[(peer, new)] = self._eager_sent.pop((peer, old))

    def carried(self) -> list[Sent]:
        """The reports of the packet just built, as pseudo-messages for the engine's `sent`."""
        out = [Sent(REPORT_KEY, named, None) for named in self._reports]
        self._reports = []
        return out

    def confirm(self) -> None:
        """After an A part was taken in: our reports the peer is now known to have received,
        and those whose packet it showed lost. A lost report that named a packet of the peer
        missing (one no report the peer received named yet) goes again on the next packet
        leaving, as a gap does (`gap`), not an `ack_interval` later: that packet may have
        carried a command the peer repairs only when told it was lost (fates.py), and a
        report lost with it otherwise costs the call two rounds."""
        for peer, epoch, largest in self.engine.confirmed:
            key = (peer, epoch)
            self._confirmed[key] = max(largest, self._confirmed.get(key, largest))
        self.engine.confirmed.clear()
        for peer, epoch, largest in self.engine.reports_lost:
            r = self.engine.receipts.get((peer, epoch))
            if r is None or r.largest is None or r.gap:
                continue
            low = self._confirmed.get((peer, epoch), min(r.got, default=r.largest) - 1)
            first = max(low + 1, r.largest - RECEIVED_WINDOW)   # what `got` remembers
            if any(n not in r.got for n in range(first, min(largest, r.largest))):
                r.gap = True
        self.engine.reports_lost.clear()

    def alone(self, now: float) -> bool:
        """A packet with only the A part: a peer has waited `ack_delay` for the ack of a
        reliable message, or has had news unreported for 2 `ack_interval`, or (at most
        IDLE_REPEATS times, 2 `ack_interval` apart) numbers of it no confirmed report named
        (this side sends nothing: the peer's ledger closes all the same)."""
        return self.final or any(self.engine.ack_only_due(peer, now) for peer, _ in self.engine.receipts) \
            or any(now - t >= 2 * self.ack_interval for t in self._news.values()) \
            or any(now >= t for t in self._idle_times())

    def _idle_times(self) -> list[float]:
        out = []
        for peer, tries in self._idle.items():
            r = self.engine._current(peer)
            low = None if r is None else self._confirmed.get((peer, self._epoch_of(peer)))
            if r is not None and tries < IDLE_REPEATS and peer not in self._news and \
                    (low is None or low < r.largest):
                out.append(self._last_report.get(peer, 0.0) + 2 * self.ack_interval)
        return out

    def _epoch_of(self, peer: int) -> bytes:
        return next((e for p, e in self.engine.receipts if p == peer), b"")

    def next_times(self) -> list[float]:
        times = [r.eliciting_since + self.ack_delay for r in self.engine.receipts.values()
                 if r.eliciting_since is not None]
        return times + [t + 2 * self.ack_interval for t in self._news.values()] + self._idle_times()


class ReportTimes:
    """When T rides with an A part (wire-format.md section 15.5; clock_offset.py): on the
    first TIMED_REPORTS after a start or a peer's new epoch, on every eager report
    (`AckPolicy._eager`: a peer with no sample of our clock yet), then one every
    TIMED_REPORT_EVERY; while fewer than CLOCK_REPLIES have left, a peer's report with T is
    answered at once (the clock exchange at start)."""

    def __init__(self, acks: AckPolicy):
        self.acks, self.sent, self.last = acks, 0, -math.inf

    def due(self, epochs: dict[int, bytes], now: float) -> bool:
        return (self.sent < TIMED_REPORTS or self.acks.eager_any(epochs)
                or now - self.last >= TIMED_REPORT_EVERY)

    def answering(self) -> bool:
        return self.sent < CLOCK_REPLIES

    def left(self, now: float) -> None:
        self.sent, self.last = self.sent + 1, now

    def restarted(self) -> None:
        """A peer's new epoch: the first TIMED_REPORTS carry T again."""
        self.sent = 0
