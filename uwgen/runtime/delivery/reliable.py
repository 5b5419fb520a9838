"""Reliable delivery over one link: acknowledgements, retransmission, delivery once
(docs/wire-format.md section 15, docs/seams.md sections 2 and 5). Pure: no sockets, no
threads; every call takes `now` from the caller's injected clock.

Every packet a side sends has a number (the envelope's W: 12 bits on the wire, unwrapped
here to a growing int). The engine is told what each packet carried, `sent(number,
[(key, ref, deadline)], now)` (deadline None: best effort, never sent again), and what the
peer's acknowledgements say, `acked(peer, a_bytes, now)`. From them it knows, per entry
`key`, what was delivered and what was lost on the link (`ledger`: exact, from packet
numbers), re-sends lost messages of reliable entries until their deadline (`due(now)`),
and measures the round trip for its retransmission timer (`RttEstimator`).

With more than one peer (a fleet) a packet is delivered once each peer in `sent(..., to=)`
acknowledged it (`acked(..., reporter=)`), lost once one reports it missing (docs/fleets.md).

As a receiver it records each peer's packet numbers (`received`), builds the A part
that acknowledges them (`ack_for`: largest number plus a bitmap of the ones before, as
SACK blocks and LTP report segments do), says when an ack must go alone because no
packet is leaving toward that peer (`ack_only_due`), and lets a reliable message through
once (`deliver_once`, by the per-entry message number of the reliable head).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Iterable

NUMBER_BITS = 12
NUMBER_MOD = 1 << NUMBER_BITS
MAX_BITMAP = 15                  # bytes of bitmap a report may carry (4 bits of R0)
DELAY_UNIT = 0.25                # s: the ack delay's unit in R1
MAX_DELAY_UNITS = 15
LOSS_THRESHOLD = 1               # a packet is lost once one later packet is acknowledged
                                 # (one acoustic path: no reordering; see wire-format 15)
RECEIVED_WINDOW = 8 * MAX_BITMAP + 1   # numbers below the largest a receiver remembers
DELIVERED_MEMORY = 128           # message numbers per entry remembered for delivery once
MESSAGE_MOD = 256                # the reliable head's message number N is one byte
REPORT_KEY = -1                  # Sent.key of an acknowledgement a packet carried (ref: what
                                 # it named); not an entry: kept out of the ledger


class AckError(ValueError):
    """An A part that is not a list of well-formed reports."""


# -- the A part ------------------------------------------------------------------------

@dataclass(frozen=True)
class Report:
    """What a receiver says about one peer's packets: `largest` (mod 4096) was received
    `delay` seconds before the report left; bit i of `bitmap` (i = 0 the packet just below
    largest) says whether largest - 1 - i was received, for `nbytes` * 8 packets."""

    peer: int
    largest: int
    bitmap: int = 0
    nbytes: int = 0
    delay: float = 0.0

    def numbers(self) -> tuple[list[int], list[int]]:
        """(received, missing) numbers mod 4096, largest first."""
        got, missing = [self.largest], []
        for i in range(8 * self.nbytes):
            n = (self.largest - 1 - i) % NUMBER_MOD
            (got if self.bitmap >> (8 * self.nbytes - 1 - i) & 1 else missing).append(n)
        return got, missing


def encode_reports(reports: Iterable[Report]) -> bytes:
    """R0 = peer (bits 7-4) | bitmap bytes n (3-0); R1 = delay in 1/4 s (7-4) | largest
    bits 11-8 (3-0); R2 = largest bits 7-0; then n bitmap bytes, packet largest-1 first."""
    out = bytearray()
    for r in reports:
        if not 0 <= r.peer <= 15 or not 0 <= r.nbytes <= MAX_BITMAP or not 0 <= r.largest < NUMBER_MOD:
            raise AckError(f"report {r} out of range")
        units = min(MAX_DELAY_UNITS, max(0, int(r.delay / DELAY_UNIT)))
        out += bytes([r.peer << 4 | r.nbytes, units << 4 | r.largest >> 8, r.largest & 0xFF])
        out += r.bitmap.to_bytes(r.nbytes, "big")
    return bytes(out)


def decode_reports(data: bytes) -> list[Report]:
    reports, i = [], 0
    while i < len(data):
        if i + 3 > len(data):
            raise AckError(f"report at byte {i} is cut short ({len(data) - i} of 3 head bytes)")
        r0, r1, r2 = data[i], data[i + 1], data[i + 2]
        n = r0 & 0x0F
        if i + 3 + n > len(data):
            raise AckError(f"report at byte {i} announces {n} bitmap bytes, "
                           f"{len(data) - i - 3} remain")
        reports.append(Report(r0 >> 4, (r1 & 0x0F) << 8 | r2,
                              int.from_bytes(data[i + 3:i + 3 + n], "big"), n,
                              (r1 >> 4) * DELAY_UNIT))
        i += 3 + n
    return reports


def unwrap(number: int, near: int) -> int:
    """The int whose low 12 bits are `number`, closest to `near`."""
    base = near - NUMBER_MOD // 2
    return base + (number - base) % NUMBER_MOD


# -- round trip --------------------------------------------------------------------------

def command_rtt(timeout: float, period: float, round_trip: float | None = None,
                turn_gap: float = 0.0) -> RttEstimator:
    """The retransmission timer of one command (service call, goal, result) whose deadline
    is `timeout` after it first left. Without a MAC's figures: a quarter of it until the link
    is measured, and never more, so at least four copies fit before the deadline (a 20 % loss
    each way fails four request/response rounds with probability 0.36^4 = 1.7 %, six with
    0.2 %). Its first value and floor are the MAC's (docs/seams.md section 7): never less than
    the link's `period` plus `turn_gap` (a reply may wait that long for the peer's turn), nor
    than `round_trip`, the least a request and its answer can take under the MAC (both ways
    across the range, and a slot under TDMA): a copy never leaves before its answer could
    have come back, however short the deadline."""
    floor = max(period + turn_gap, round_trip or 0.0)
    quarter = max(timeout / 4, floor)
    return RttEstimator(quarter, floor, quarter, period)


class RttEstimator:
    """RFC 6298's smoothed round trip and variance, with acoustic bounds: the first RTO is
    a guess (`initial`), every sample replaces it; `granularity` is the link's period (no
    packet leaves faster); `backoff()` doubles the RTO after a timeout, up to `maximum`."""

    def __init__(self, initial: float, minimum: float, maximum: float, granularity: float):
        self.rto, self.minimum, self.maximum, self.granularity = initial, minimum, maximum, granularity
        self.srtt: float | None = None
        self.rttvar = 0.0
        self.samples = 0

    def sample(self, rtt: float) -> None:
        rtt = max(rtt, 0.0)
        if self.srtt is None:
            self.srtt, self.rttvar = rtt, rtt / 2
        else:
            self.rttvar = 0.75 * self.rttvar + 0.25 * abs(self.srtt - rtt)
            self.srtt = 0.875 * self.srtt + 0.125 * rtt
        self.samples += 1
        self.rto = min(self.maximum, max(self.minimum,
                                         self.srtt + max(self.granularity, 4 * self.rttvar)))

    def backoff(self) -> None:
        self.rto = min(self.maximum, 2 * self.rto)


# -- sending side ------------------------------------------------------------------------

@dataclass
class Sent:
    """One message as a packet carried it: `ref` is the sender's handle to send it again."""

    key: int
    ref: Any
    deadline: float | None          # None: best effort


@dataclass
class EntryLedger:
    """Per entry (link key), on the sending side; all counts are messages."""

    sent: int = 0                   # messages put in packets (each copy counts)
    delivered: int = 0              # copies the peer acknowledged
    lost_on_link: int = 0           # copies the peer's acks say never arrived
    resent: int = 0                 # reliable messages handed back by due()
    expired: int = 0                # reliable messages lost with their deadline passed
    unacknowledged: int = 0         # copies in packets no ack named before they were forgotten
    unknown: int = 0                # copies sent before the peer restarted that its new start
                                    # reports missing: its old start may have had them


@dataclass
class _Packet:
    number: int
    at: float
    messages: list[Sent]
    timed_out: bool = False
    fate_unknown: bool = False      # sent before the peer's restart was seen
    waiting: set[int] | None = None   # peers whose ack it still needs (None: anyone's)

    def awaits(self, reporter: int | None) -> bool:
        """Whether a report of `reporter` speaks for this packet."""
        return self.waiting is None or reporter is None or reporter in self.waiting


@dataclass
class PeerReceipts:
    """A receiver's record of one peer's (sender id, epoch) packet numbers."""

    largest: int | None = None
    got: set[int] = field(default_factory=set)      # numbers in the window below largest
    largest_at: float = 0.0
    unacked: int = 0                                # eliciting packets since our last ack
    eliciting_since: float | None = None
    duplicates: int = 0
    gaps: int = 0                                   # numbers that left the window unreceived


class ReliableLink:
    """The engine of one side: its sent packets and every peer's received packets."""

    def __init__(self, me: int, rtt: RttEstimator, *, ack_delay: float, bitmap_bytes: int = 2):
        self.me = me
        self.rtt = rtt
        self.ack_delay = ack_delay           # how long an ack may wait for a packet to ride on
        self.bitmap_bytes = min(MAX_BITMAP, bitmap_bytes)
        self.ledger: dict[int, EntryLedger] = {}
        self.outstanding: OrderedDict[int, _Packet] = OrderedDict()
        self.largest_sent: int | None = None
        self.largest_acked: int | None = None
        self._due: list[Sent] = []
        self.receipts: dict[tuple[int, bytes], PeerReceipts] = {}
        self._delivered: dict[tuple[int, bytes, int], OrderedDict[int, None]] = {}
        self.duplicates: dict[int, int] = {}          # key -> reliable copies delivered twice
        self.spurious = 0                              # retransmissions whose first copy arrived
        self.bad_acks = 0
        self.confirmed: list[Any] = []                 # refs of our reports the peer received

    def entry(self, key: int) -> EntryLedger:
        return self.ledger.setdefault(key, EntryLedger())

    # -- what left -------------------------------------------------------------------------

    def sent(self, number: int, messages: list[Sent], now: float,
             to: Iterable[int] | None = None) -> None:
        """Packet `number` (unwrapped, growing) left now carrying `messages`, for peers `to`
        (None: the first report settles it)."""
        for m in messages:
            if m.key != REPORT_KEY:
                self.entry(m.key).sent += 1
        waiting = None if to is None else set(to)
        self.outstanding[number] = _Packet(number, now, list(messages), waiting=waiting)
        self.largest_sent = number

    def acked(self, data: bytes, now: float, reporter: int | None = None) -> None:
        """An A part arrived (from peer `reporter`, when known); reports about other senders
        are ignored. Bad bytes: counted."""
        try:
            reports = decode_reports(data)
        except AckError:
            self.bad_acks += 1
            return
        for report in reports:
            if report.peer == self.me and self.largest_sent is not None:
                self._report(report, now, reporter)

    def _report(self, report: Report, now: float, reporter: int | None = None) -> None:
        largest = unwrap(report.largest, self.largest_sent)
        if largest > self.largest_sent:
            self.bad_acks += 1                  # names a packet never sent
            return
        got, missing = report.numbers()
        newest = None
        for n in got:
            packet = self.outstanding.get(unwrap(n, largest))
            if packet is None or not packet.awaits(reporter):
                continue
            newest = packet if newest is None or packet.number > newest.number else newest
            if packet.waiting is not None and reporter is not None:
                packet.waiting.discard(reporter)
                if packet.waiting:
                    continue                    # other peers have yet to acknowledge it
            del self.outstanding[packet.number]
            self._delivered_packet(packet)
        if newest is not None and newest.number == largest and not newest.timed_out:
            self.rtt.sample(now - newest.at - min(report.delay, now - newest.at))
        if self.largest_acked is None or largest > self.largest_acked:
            self.largest_acked = largest
        for n in missing:
            number = unwrap(n, largest)
            packet = self.outstanding.get(number)
            if largest - number >= LOSS_THRESHOLD and packet is not None and packet.awaits(reporter):
                self._lost(self.outstanding.pop(number), now)
        # Packets below what this report can name were never acknowledged: lost.
        floor = largest - 8 * report.nbytes
        for number in [n for n, p in self.outstanding.items() if n < floor and p.awaits(reporter)]:
            self._lost(self.outstanding.pop(number), now)

    def _delivered_packet(self, packet: _Packet) -> None:
        for m in packet.messages:
            if m.key == REPORT_KEY:
                self.confirmed.append(m.ref)
                continue
            self.entry(m.key).delivered += 1
        if packet.timed_out:
            self.spurious += 1

    def peer_restarted(self) -> None:
        """The peer started again (a new epoch): what it did not get of the packets sent so
        far may have reached its previous start, so those are counted `unknown`, not lost
        (their reliable messages are still sent again: the new start has no memory of them)."""
        for packet in self.outstanding.values():
            packet.fate_unknown = True

    def _lost(self, packet: _Packet, now: float) -> None:
        for m in packet.messages:
            if m.key == REPORT_KEY:
                continue
            if packet.fate_unknown:
                self.entry(m.key).unknown += 1
            else:
                self.entry(m.key).lost_on_link += 1
            if not packet.timed_out:
                self._again(m, now)

    def _again(self, m: Sent, now: float) -> None:
        if m.deadline is None:
            return
        if m.deadline <= now:
            self.entry(m.key).expired += 1
            return
        self.entry(m.key).resent += 1
        self._due.append(m)

    def due(self, now: float) -> list[Sent]:
        """Reliable messages to send again now: those the peer said it lost, and those of
        packets unacknowledged for an RTO (then the RTO backs off). Each is handed out once
        per loss; its next copy goes in a new packet with a new number."""
        for packet in self.outstanding.values():
            if packet.timed_out or now - packet.at < self.rtt.rto + self.ack_delay:
                continue
            if any(m.deadline is not None for m in packet.messages):
                packet.timed_out = True
                self.rtt.backoff()
                for m in packet.messages:
                    self._again(m, now)
        out, self._due = self._due, []
        return out

    def next_timeout(self) -> float | None:
        """When due() will next have something (None: nothing reliable waits). The timer of
        a packet is the RTO plus the peer's ack delay (an ack may wait that long for a
        packet to ride on; the RTO itself is measured without it)."""
        if self._due:
            return float("-inf")
        times = [p.at + self.rtt.rto + self.ack_delay for p in self.outstanding.values()
                 if not p.timed_out and any(m.deadline is not None for m in p.messages)]
        return min(times) if times else None

    # -- what arrived ------------------------------------------------------------------------

    def received(self, peer: int, epoch: bytes, number: int, now: float,
                 eliciting: bool) -> bool:
        """Packet `number` (mod 4096) from (peer, epoch) arrived. False: a duplicate packet
        (counted; its messages must not be delivered). `eliciting`: it carries a reliable
        message, so the peer waits for an ack of it."""
        r = self.receipts.get((peer, epoch))
        if r is None:
            # A new epoch is a restarted peer: everything known about the old one goes.
            for old in [k for k in self.receipts if k[0] == peer]:
                del self.receipts[old]
            r = self.receipts[(peer, epoch)] = PeerReceipts()
        n = number if r.largest is None else unwrap(number, r.largest)
        if r.largest is not None and (n == r.largest or n in r.got):
            r.duplicates += 1
            return False
        if r.largest is not None and n < r.largest - RECEIVED_WINDOW:
            r.duplicates += 1                   # too old to tell: treated as a repeat
            return False
        if r.largest is None or n > r.largest:
            if r.largest is not None:
                r.got.add(r.largest)
                low = n - RECEIVED_WINDOW
                r.got = {x for x in r.got if x >= low}
                r.gaps += n - r.largest - 1          # numbers skipped (missing so far)
            r.largest, r.largest_at = n, now
        else:
            r.got.add(n)
            r.gaps -= 1                          # a number counted missing came after all
        if eliciting:
            r.unacked += 1
            if r.eliciting_since is None:
                r.eliciting_since = now
        return True

    def in_flight(self) -> dict[int, int]:
        """Per entry, copies in packets not acknowledged nor known lost yet."""
        out: dict[int, int] = {}
        for packet in self.outstanding.values():
            for m in packet.messages:
                if m.key != REPORT_KEY:
                    out[m.key] = out.get(m.key, 0) + 1
        return out

    def forget(self, below: int) -> None:
        """Give up on packets numbered below `below` that no ack named (a peer that never
        acknowledges, or numbers too old to name unambiguously): `unacknowledged`."""
        while self.outstanding:
            number, packet = next(iter(self.outstanding.items()))
            if number >= below:
                break
            del self.outstanding[number]
            for m in packet.messages:
                if m.key != REPORT_KEY:
                    self.entry(m.key).unacknowledged += 1

    def ack_for(self, peer: int, now: float, *, any_news: bool = True,
                nbytes: int | None = None) -> bytes | None:
        """The A part about `peer`'s packets for a packet leaving now (None: nothing to say).
        Sent when packets of the peer arrived since our last ack (`unacked`); with
        `any_news` False only when the peer waits for one (eliciting packets)."""
        r = self._current(peer)
        if r is None or r.largest is None or (r.unacked == 0 and r.eliciting_since is None
                                              and not any_news):
            return None
        nbytes = self.bitmap_bytes if nbytes is None else max(0, min(MAX_BITMAP, nbytes))
        bitmap = 0
        for i in range(8 * nbytes):
            bitmap = bitmap << 1 | ((r.largest - 1 - i) in r.got)
        r.unacked, r.eliciting_since = 0, None
        return encode_reports([Report(peer, r.largest % NUMBER_MOD, bitmap, nbytes,
                                      now - r.largest_at)])

    def ack_only_due(self, peer: int, now: float) -> bool:
        """True when the peer waits for an ack and none has ridden on a packet for
        `ack_delay`: the link should send a packet with only the A part."""
        r = self._current(peer)
        return r is not None and r.eliciting_since is not None and now - r.eliciting_since >= self.ack_delay

    def rename_epoch(self, peer: int, old: bytes, new: bytes) -> None:
        """What was kept of `peer` under a stand-in epoch (`old`: not known yet) is its epoch
        `new`, learnt from K: the same start, not a restart."""
        r = self.receipts.pop((peer, old), None)
        if r is not None:
            self.receipts[(peer, new)] = r
        for (p, e, key) in [k for k in self._delivered if k[0] == peer and k[1] == old]:
            self._delivered[(p, new, key)] = self._delivered.pop((p, e, key))

    def _current(self, peer: int) -> PeerReceipts | None:
        for (p, _epoch), r in self.receipts.items():
            if p == peer:
                return r
        return None

    def deliver_once(self, sender: int, epoch: bytes, key: int, msg_id: int) -> bool:
        """True the first time a reliable message (its head's number N) arrives; False for a
        copy (counted in `duplicates[key]`)."""
        seen = self._delivered.setdefault((sender, epoch, key), OrderedDict())
        if msg_id in seen:
            self.duplicates[key] = self.duplicates.get(key, 0) + 1
            return False
        seen[msg_id] = None
        while len(seen) > DELIVERED_MEMORY:
            seen.popitem(last=False)
        return True
