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

As a receiver (`uwgen.runtime.delivery.receiving.Receiving`) it records each peer's packet
numbers, builds the A part that acknowledges them and lets a reliable message through once;
the A part's bytes are `uwgen.runtime.delivery.reports`.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any, Iterable

from uwgen.runtime.delivery.copies import Copies
from uwgen.runtime.delivery.receiving import (DELIVERED_MEMORY, RECEIVED_WINDOW,  # noqa: F401
                                              PeerReceipts, Receiving)
from uwgen.runtime.delivery.reports import (DELAY_UNIT, MAX_BITMAP, MAX_DELAY_UNITS,  # noqa: F401
                                            NUMBER_BITS, NUMBER_MOD, AckError, Report,
                                            decode_reports, encode_reports, unwrap)

LOSS_THRESHOLD = 1               # a packet is lost once one later packet is acknowledged
FATES_KEPT = 256                 # settled packets whose fate a cut message's head may ask
                                 # (one acoustic path: no reordering; see wire-format 15)
MESSAGE_MOD = 256                # the reliable head's message number N is one byte
REPORT_KEY = -1                  # Sent.key of an acknowledgement a packet carried (ref: what
                                 # it named); not an entry: kept out of the ledger


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
    tail: int | None = None         # a cut message: the packet its tail rides in (14.2)
    ident: int | None = None        # a reliable message: the same for all its copies (copies.py)


def wire_id(key: int) -> int:
    """The wire id of a link channel key (an action's feedback channel is 256 + id)."""
    return key - 256 if key >= 256 else key


def packet_peers(messages: list[Sent], destinations: dict[int, frozenset[int]] | None,
                 everyone: frozenset[int]) -> set[int] | None:
    """The peers a packet must reach: those its messages are for (`destinations`: wire id ->
    peers; `everyone` for an id not in it), and those its reports are about (None without
    destinations: two sides, the first report settles it)."""
    if destinations is None:
        return None
    to: set[int] = set()
    for m in messages:
        if m.key == REPORT_KEY:
            to.add(m.ref[0])
        else:
            to |= destinations.get(wire_id(m.key), everyone)
    return to


class Told:
    """Command messages' fates as reports settle their packets (docs/wire-format.md section
    15.6, "A command's fate"): for the `watched` keys, each whole message's (key, ref,
    arrived) in `fates` until taken. A packet's are told once: one overtaken (lost, as a
    later report shows under turns) is not told again when a report names it."""

    def __init__(self):
        self.watched: frozenset[int] = frozenset()
        self.fates: list[tuple[int, Any, bool]] = []

    def tell(self, packet: _Packet, arrived: bool) -> None:
        """A cut message arrived only with its tail (`cut`), but is lost with its head."""
        if packet.told or not self.watched:
            return
        packet.told = True
        self.fates += [(m.key, m.ref, arrived) for m in packet.messages
                       if m.key in self.watched and (m.tail is None or not arrived)]

    def cut(self, m: Sent, arrived: bool) -> None:
        """A cut message whose head arrived after its tail's packet had settled."""
        if m.key in self.watched:
            self.fates.append((m.key, m.ref, arrived))

    def take(self) -> list[tuple[int, Any, bool]]:
        out, self.fates = self.fates, []
        return out


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
    told: bool = False              # its command messages' fate was told (ReliableLink._tell)

    def awaits(self, reporter: int | None) -> bool:
        """Whether a report of `reporter` speaks for this packet."""
        return self.waiting is None or reporter is None or reporter in self.waiting


class ReliableLink(Receiving):
    """The engine of one side: its sent packets and every peer's received packets."""

    def __init__(self, me: int, rtt: RttEstimator, *, ack_delay: float, bitmap_bytes: int = 2):
        super().__init__(bitmap_bytes)
        self.me = me
        self.rtt = rtt
        self.ack_delay = ack_delay           # how long an ack may wait for a packet to ride on
        self.ledger: dict[int, EntryLedger] = {}
        self.outstanding: OrderedDict[int, _Packet] = OrderedDict()
        self.largest_sent: int | None = None
        self.largest_acked: int | None = None
        self._due: list[Sent] = []
        self.spurious = 0                              # retransmissions whose first copy arrived
        self.fast_resends = 0                          # reliable messages a report showed lost
        self.timer_resends = 0                         # reliable messages whose timer ran out
        self.bad_acks = 0
        self.confirmed: list[Any] = []                 # refs of our reports the peer received
        self.reports_lost: list[Any] = []              # refs of our reports whose packet was lost
        # recently settled packets' fates (True: acked), for cut messages' tails settled later
        self._fates: OrderedDict[int, bool] = OrderedDict()
        self._moved: Sent | None = None     # a message the next packet carries whole (cut)
        self.spare = Copies()               # copies of reliable messages, the measured loss
        self.reported_at = -float("inf")    # when the last report about our packets came
        self.told = Told()                  # command messages' fates, as reports settle them

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
        self.spare.went(messages)
        waiting = None if to is None else set(to)
        if self._moved is not None:         # counted sent with the packet it was taken for
            messages, self._moved = [*messages, self._moved], None
        self.outstanding[number] = _Packet(number, now, list(messages), waiting=waiting)
        self.largest_sent = number

    def acked(self, data: bytes, now: float, reporter: int | None = None,
              settled_by: float | None = None) -> None:
        """An A part arrived (from peer `reporter`, when known); reports about other senders
        are ignored. Bad bytes: counted. `settled_by`: every packet this side sent until then
        had reached the reporter, or was lost, before the report was built (the MAC knows it:
        the report rides in a turn that began after them), so one the report does not name is
        lost: its reliable messages go again now (`overtaken`), not after the timer."""
        try:
            reports = decode_reports(data)
        except AckError:
            self.bad_acks += 1
            return
        for report in reports:
            if report.peer == self.me and self.largest_sent is not None:
                self.reported_at = now
                self._report(report, now, reporter, settled_by)

    def _report(self, report: Report, now: float, reporter: int | None = None,
                settled_by: float | None = None) -> None:
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
            self.spare.gone(packet)
            self._delivered_packet(packet)
        # Karn: no sample from a packet timed out; none either when the report held its
        # largest longer than R1 can say (its delay is the most R1 holds): the held time is
        # not known, and taken off short it would read as a round trip seconds longer
        if newest is not None and newest.number == largest and not newest.timed_out \
                and report.delay < MAX_DELAY_UNITS * DELAY_UNIT:
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
        if settled_by is not None:
            for packet in list(self.outstanding.values()):
                if packet.number > largest and packet.at <= settled_by and packet.awaits(reporter):
                    self.overtaken(packet, now)

    def overtaken(self, packet: _Packet, now: float) -> None:
        """A packet sent after the report's largest that the report would have named had it
        arrived: its reliable messages go again now. It stays outstanding, as after a timeout
        (a later report names its fate for the ledger; should it have arrived after all, the
        copy is `spurious` and delivered once)."""
        self.told.tell(packet, False)
        if packet.timed_out or all(m.deadline is None for m in packet.messages):
            return
        self._give_up(packet)
        for m in packet.messages:
            self._again(m, now, fast=True)

    def cut(self, number: int, moved: bool = False) -> None:
        """Packet `number`'s last message was cut (wire format 14.2): it reached the peer only
        if the next packet, which carries its tail, did too. `moved`: it went whole in the
        next packet instead, whose fate alone is its own."""
        packet = self.outstanding.get(number)
        mine = [m for m in packet.messages if m.key != REPORT_KEY] if packet is not None else []
        if not mine:
            return
        if moved:
            packet.messages.remove(mine[-1])
            self._moved = replace(mine[-1], tail=None)
        else:
            mine[-1].tail = number + 1

    def _settled(self, number: int, arrived: bool) -> None:
        self.spare.settled(arrived)
        self._fates[number] = arrived
        while len(self._fates) > FATES_KEPT:
            self._fates.popitem(last=False)

    def _delivered_packet(self, packet: _Packet) -> None:
        self._settled(packet.number, True)
        self.told.tell(packet, True)
        for m in packet.messages:
            if m.key == REPORT_KEY:
                self.confirmed.append(m.ref)
                continue
            self.spare.arrived(m)
            if m.tail is not None:
                # the head arrived; the message did if its tail did
                tail = self.outstanding.get(m.tail)
                if tail is not None:
                    tail.messages.append(replace(m, tail=None))
                    continue
                fate = self._fates.get(m.tail)
                if fate is None:
                    self.entry(m.key).unacknowledged += 1
                    continue
                self.told.cut(m, fate)
                if not fate:
                    self.entry(m.key).lost_on_link += 1
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
        self._settled(packet.number, False)
        self.told.tell(packet, False)
        self.spare.gone(packet)
        for m in packet.messages:
            if m.key == REPORT_KEY:
                self.reports_lost.append(m.ref)    # acks.AckPolicy.confirm: named again
                continue
            if packet.fate_unknown:
                self.entry(m.key).unknown += 1
            else:
                self.entry(m.key).lost_on_link += 1
            if not packet.timed_out:
                self._again(m, now, fast=True)

    def _give_up(self, packet: _Packet) -> None:
        """`packet`'s reliable messages go again: its copies are no longer on their way."""
        self.spare.gone(packet)
        packet.timed_out = True

    def _again(self, m: Sent, now: float, fast: bool = False) -> None:
        if m.deadline is None or not self.spare.needed(m):
            return                          # best effort, or another copy arrived or is on its way
        if m.deadline <= now:
            self.entry(m.key).expired += 1
            return
        self.entry(m.key).resent += 1
        if fast:
            self.fast_resends += 1
        else:
            self.timer_resends += 1
        self._due.append(m)

    def due(self, now: float) -> list[Sent]:
        """Reliable messages to send again now: those the peer said it lost, and those of
        packets unacknowledged for an RTO (then the RTO backs off). Each is handed out once
        per loss; its next copy goes in a new packet with a new number."""
        for packet in self.outstanding.values():
            if packet.timed_out or now - packet.at < self.rtt.rto + self.ack_delay:
                continue
            if any(m.deadline is not None for m in packet.messages):
                self._give_up(packet)
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
            self.spare.gone(packet)
            for m in packet.messages:
                if m.key != REPORT_KEY:
                    self.entry(m.key).unacknowledged += 1
