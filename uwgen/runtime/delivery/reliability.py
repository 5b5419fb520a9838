"""Reliable delivery wired into a wire format 2 link (docs/wire-format.md section 15).

`Reliability(...).hooks()` is reliability's `PacketHooks` (docs/seams.md section 5); the
bridge joins it with the seal's (`hooks.join_hooks`) and passes it to `Link(hooks=)`. It
drives the pure engine `uwgen.runtime.delivery.reliable.ReliableLink`:

- sending: every packet's messages are told to the engine (`sent`), with the deadline of
  messages of reliable entries (publication + ttl); an A part acknowledging the peers'
  packets rides on packets that leave anyway (when a peer waits for an ack of a reliable
  message, or every `ack_interval` while there is news), and a packet with only the A part
  leaves when a peer has waited `ack_delay` for one; messages the peer lost (reliable
  entries) are sent again first (`resend`), until their deadline;
- receiving: every envelope's number feeds the engine (`received`) and its A part the
  sender's ledger (`acked`); each whole message's head is taken off (`admit`): a reliable
  message is delivered once (copies counted `duplicates`), a message with a max age is
  refused when older (`stale`, uwgen.runtime.delivery.staleness);
- T (the packet's time, `freshness.stamp` of the injected wall clock) goes on every packet
  carrying a message with a max age.

The per-entry ledger (`ledger()`, in the link's stats as `ledger`) is exact from packet
numbers: sent = delivered + lost_on_link + in_flight + unacknowledged + unknown, per channel
key (`unknown`: sent before the peer restarted, reported missing by its new start).

Epochs (docs/seams.md section 8): every wire-format-2 link carries the sender's per-start epoch
in K. A sealed link's K is the seal's; on an unsealed one (`epoch_source` given) this side
numbers its packets and gives K (`uwgen.runtime.delivery.epoch`). A receiver keys a sender's
packets and reliable messages by (sender, epoch): a new epoch is a restart, never repeats.
Everything is called on the link's thread except `stats()`; a lock keeps them apart.
"""
from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, replace

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import WALL_CLOCK, Clock
from uwgen.runtime.wire.framing import MAX_FRAME, MAX_PAYLOAD, SHORT_OVERHEAD
from uwgen.runtime.delivery.freshness import MAX_AGE, TICKS_PER_SECOND, stamp
from uwgen.runtime.wire.heads import HeadError, Heads
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.delivery.acks import A_ROOM, TIMED_REPORTS, AckPolicy, ReportTimes
from uwgen.runtime.delivery.echoes import Echoes
from uwgen.runtime.delivery.silence import Silence
from uwgen.runtime.delivery.repairs import Repairs
from uwgen.runtime.delivery.reliable import (REPORT_KEY, ReliableLink, RttEstimator, Sent,
                                             packet_peers, wire_id)
from uwgen.runtime.delivery.judge import AgeJudge
from uwgen.runtime.delivery.epoch import PeerEpochs, SendEpoch
from uwgen.runtime.stats import Counters, log_count

log = logging.getLogger("uwgen.link.reliability")

COUNTERS = ("stale", "clock_offset", "unexplained_delay", "unmeasured", "offset_samples", "bad_heads", "bad_acks", "untimed", "restarts_seen",
            "duplicate_packets")
COMMAND_KINDS = (2, 3)            # a request's and an answer's message kinds (wire format 1)
DEFAULT_DEADLINE = 120.0          # seconds: a reliable entry without a ttl
FORGET_AFTER = 2048               # packets: older ones cannot be named unambiguously (12 bits)
TRANSFERS_KEPT = 64              # fragmented messages whose first packet time is kept
# T, and an A part of one report (acks.A_ROOM): the most the hooks add to a packet.
OVERHEAD = env.TIME_LEN + A_ROOM
PROBES, PROBE_EVERY = 10, 1.0     # packets with T alone while no peer's offset is known


class Reliability:
    """One side's reliability on one link (see the module docstring)."""

    def __init__(self, sender: int, *, period: float, reliable: dict[int, float | None],
                 max_ages: dict[int, float], wall: Clock = WALL_CLOCK,
                 ack_delay: float | None = None, ack_interval: float | None = None,
                 name: str = "link", max_read_length: int = MAX_FRAME,
                 other_overhead: int = 0, peer_names: dict[int, str] | None = None,
                 epoch_source: Callable[[], bytes] | None = None, turn_gap: float = 0.0,
                 clock_exchange: bool = False, destinations: dict[int, frozenset[int]] | None = None,
                 settled_by: Callable[[int, float], float | None] | None = None,
                 unheard: Callable[[int], float | None] | None = None,
                 copies: int = 3, commands: frozenset[int] = frozenset(), own_span: float = 0.0):
        self.sender, self.name, self.wall = sender, name, wall
        # the MAC's `settled_by(peer, now)`: until when this side's packets had all reached the
        # peer or been lost before the peer's packet heard now was built (turns: the peer
        # answers in a turn that began after them); a report there names a loss at once
        self.settled_by = settled_by or (lambda peer, now: None)
        # wire id -> the peers (sender ids) its messages are for, on a channel shared by more
        # than two sides (a fleet): a packet is acknowledged by each of them (ReliableLink).
        # None: two sides, the first report settles a packet.
        self.destinations = destinations
        self._everyone = frozenset().union(*destinations.values()) if destinations else frozenset()
        # this side's epoch and numbers on an unsealed link (None: the seal gives K)
        self.send_epoch = SendEpoch(epoch_source) if epoch_source is not None else None
        self._sync = False                            # the packet being built carries K
        self._building = 0                            # its number
        # what a packet may hold besides P, W and the messages: the frame's payload minus what
        # the other joined hooks (the seal) may add; the A part takes what is left (acks.A_ROOM
        # at least, kept free by `overhead`)
        self._part_room = (min(max_read_length, MAX_PAYLOAD + SHORT_OVERHEAD) - SHORT_OVERHEAD
                           - env.HEAD - other_overhead)           # wire format 3's short frame
        self._room = 0
        self.deadlines = {k: (DEFAULT_DEADLINE if t is None else t) for k, t in reliable.items()}
        self.max_ages = dict(max_ages)
        self.heads = Heads(numbered=frozenset(wire_id(k) for k in reliable),
                           aged=frozenset(max_ages),
                           lone=frozenset(i for i, age in max_ages.items() if age <= MAX_AGE))
        self.ack_delay = ack_delay if ack_delay is not None else max(1.0, 4 * period)
        self.ack_interval = (ack_interval if ack_interval is not None   # news: every 2nd
                             else max(2.0, 8 * period, 2 * turn_gap))     # MAC round (15.2)
        # The retransmission timer's first value and floor are the MAC's (docs/seams.md
        # section 6): a reply may wait `turn_gap` for the peer's turn, besides a period.
        first = max(2.0, 8 * period) + turn_gap
        self.engine = ReliableLink(sender, RttEstimator(first, period + turn_gap, 60.0, period),
                                   ack_delay=self.ack_delay)
        self._want_time = False
        self._probes, self._next_probe = 0, -float("inf")   # clock probes sent, the next one
        self.clock_exchange = clock_exchange          # probe and answer at start (the bridge's)
        self.counters = Counters(COUNTERS)
        # commands' ages, with each peer's clock offset measured from exchanges (judge.py)
        self.judge = AgeJudge(sender, name, wall, self.counters, self.max_ages, peer_names,
                              measured_only=clock_exchange)
        self.offsets, self.stale_by_id = self.judge.offsets, self.judge.stale_by_id
        self.first_offset_at = self.judge.first_offset_at
        self._lock = threading.Lock()
        self._deadline_of: dict[int, float] = {}      # channel key -> its message being sent
        self._timed = False                           # the packet being built needs T
        self.engine.spare.limit = copies              # most copies in spare room (copies.py)
        self.echoes = Echoes(frozenset(commands), own_span, self.heads, self.engine.spare)
        self._command_ids = frozenset(wire_id(k) for k in commands)
        # a command's fate, as the peer's reports tell it, goes to the bridge (section 15.6, "A
        # command's fate"): (key, payload as offered, arrived), on the link's thread, unlocked
        self.engine.told.watched = frozenset(commands)
        self.on_fate: Callable[[int, bytes, bool], None] | None = None
        self.report_bytes = 0                         # A parts written (with their length byte)
        self.repairs = Repairs(self.engine, self.echoes, self.heads, self.deadlines)
        self.silence = Silence(self.engine)           # a peer's packet with no report (15.2)
        self.acks = AckPolicy(self.engine, ack_delay=self.ack_delay, ack_interval=self.ack_interval,
                              eager=TIMED_REPORTS if clock_exchange and self.max_ages else 0,
                              unheard=unheard)      # the MAC's: a peer's turn went unheard
        self.report_times = ReportTimes(self.acks)    # when T rides with an A part
        self._peers = PeerEpochs()                    # each peer's epoch, as received
        self._epochs = self._peers.known
        self._rx: tuple[int, bytes, int | None] | None = None
        self._transfer_t: OrderedDict[tuple[int, bytes, int], int] = OrderedDict()

    def hooks(self) -> PacketHooks:
        # Unsealed: this side numbers the packets (K names its epoch). K is not in `overhead`
        # (which sizes fragments): it rides when the packet has room for it (`carrying`).
        numbering = {} if self.send_epoch is None else {"number": self.number}
        return PacketHooks(parts=self.parts, sent=self.sent, received=self.received,
                           overhead=OVERHEAD, next_overhead=self.next_overhead,
                           part_room=self.part_room, carrying=self.carrying, resend=self.resend,
                           copy=self.copy, cut=self.cut,
                           ack_only=self.ack_only, next_time=self.next_time, stamp=self.stamp,
                           head_room=self.head_room, admit=self.admit,
                           shape=self.shape, unshape=self.heads.with_age, stats=self.stats,
                           **numbering)

    def number(self) -> int:
        with self._lock:
            self._building = self.send_epoch.number()
            return self._building

    # -- sending ------------------------------------------------------------------------

    def next_overhead(self, now: float) -> int:
        """Room for the parts due on the next packet (docs/seams.md section 9): an A part (and
        T with it), or K, T and an A part's share; T of a message with a max age: `part_room`."""
        with self._lock:
            ack = self.acks.due(self._epochs, now)
            timed = ack and self.report_times.due(self._epochs, now)
            if self.send_epoch is not None and self.send_epoch.due(now):   # as `carrying` asks
                return env.SYNC_LEN + env.TIME_LEN + A_ROOM
            return (A_ROOM if ack else 0) + (env.TIME_LEN if timed else 0)

    def part_room(self, key: int) -> int:
        """T (3 bytes, once a packet) for a message of an entry with a max age."""
        return env.TIME_LEN if wire_id(key) in self.max_ages else 0

    def shape(self, envelope: env.Envelope) -> env.Envelope:
        """The packet as it leaves: a lone message with a max age gives T its publication
        time and leaves its age item out (wire-format.md section 14.3; `Heads.with_age` puts it
        back at the receiver)."""
        return self.heads.without_age(envelope, TICKS_PER_SECOND)

    def head_room(self, key: int) -> int:
        return self.heads.room(wire_id(key))

    def stamp(self, key: int, payload: bytes, born: float, now: float) -> bytes:
        with self._lock:
            if key in self.deadlines:
                self._deadline_of[key] = born + self.deadlines[key]
            stamped, _ = self.heads.add(payload, now - born)
            return stamped

    def carrying(self, picked: list[tuple[int, bytes]], now: float, fresh: bool = True) -> None:
        self._timed = any(wire_id(key) in self.max_ages for key, _ in picked)
        self.echoes.carrying(picked)
        # T also goes with the A part at a start, while a report is eager, then now and
        # then, so the peer measures our clock's offset (acks.ReportTimes)
        self._want_time = self._timed or self.report_times.due(self._epochs, now)
        # what the messages take as the envelope encodes them (runs share a head)
        used = len(env.encode_messages([env.from_v1(p) for _, p in picked]))
        # K when due and the packet has room for it besides T and the A part's share (a
        # packet filled by a full-size fragment carries it on a later one)
        self._sync = (self.send_epoch is not None and self.send_epoch.due(now)
                      and self._part_room - used - env.TIME_LEN - env.SYNC_LEN >= A_ROOM)
        self._room = (self._part_room - used - (env.TIME_LEN if self._want_time or self._sync else 0)
                      - (env.SYNC_LEN if self._sync else 0))

    def parts(self, now: float) -> dict:
        with self._lock:
            out: dict = {}
            ack = self.acks.a_part(self._epochs, now, self._room)
            if ack:
                out["ack"] = ack
                self.report_bytes += 1 + len(ack)
                self.acks.final = False              # the last word has left (farewell)
            if self._sync:
                out["sync"] = self.send_epoch.part(self._building, now)
            probe = self._probing() and now >= self._next_probe
            if probe:
                self._probes += 1
                self._next_probe = now + PROBE_EVERY
            if self._timed or self._sync or (ack and self._want_time) or probe:
                out["time"] = stamp(self.wall.now())
                if ack:
                    self.report_times.left(now)
            return out

    def sent(self, number: int, picked: list[tuple[int, bytes]], now: float) -> None:
        with self._lock:
            messages = []
            for key, payload in picked:
                m = self.repairs.resending.pop(id(payload), None)   # a copy: its message's identity
                if m is None:
                    deadline = self._deadline_of.get(key)
                    m = Sent(key, None, deadline, ident=None if deadline is None
                             else self.engine.spare.new_ident())
                messages.append(replace(m, ref=payload, tail=None))
            self.repairs.resending.clear()
            self.echoes.left(number, picked, now)
            messages += self.acks.carried()      # its reports: confirmed once it is acked
            self.engine.sent(number, messages, now,
                             packet_peers(messages, self.destinations, self._everyone))
            self.silence.sent(number)
            self.offsets.built(number, self.wall.now())
            self.engine.forget(number - FORGET_AFTER)
            self._timed = False

    def cut(self, number: int, moved: bool = False) -> None:
        """Packet `number`'s last message was cut (or, `moved`, goes whole in the next packet):
        the ledger waits for the next packet's fate too (wire-format.md section 14.2)."""
        with self._lock:
            self.engine.cut(number, moved)
            self.echoes.cut(number)

    def repeat(self, key: int, payload: bytes) -> None:
        """The bridge offers a command again (echoes.py: it gets a copy in its turn)."""
        with self._lock:
            self.echoes.repeat(key, payload)

    def resend(self, now: float, room: int) -> tuple[int, bytes] | None:
        with self._lock:
            return self.repairs.resend(now, room)

    def copy(self, now: float, room: int, fresh: bool = True) -> tuple[int, bytes] | None:
        with self._lock:
            return self.repairs.copy(now, room, fresh)

    def ack_only(self, now: float) -> bool:
        with self._lock:
            return self.acks.alone(now) or (self._probing() and now >= self._next_probe)

    def farewell(self) -> bool:
        """Closing: the next packet reports every peer's packets, so their ledgers close (a
        clean stop leaves nothing `in_flight` there). False when there is nothing to report."""
        with self._lock:
            self.acks.final = any(r.largest is not None for r in self.engine.receipts.values())
            return self.acks.final

    @property
    def farewell_pending(self) -> bool:
        with self._lock:
            return self.acks.final

    def next_time(self, now: float) -> float | None:
        with self._lock:
            if self.repairs.queue or self.acks.final or self.echoes.waiting(now):
                return now
            times = [t for t in [self.engine.next_timeout()] if t is not None]
            times += self.acks.next_times()
            if self._probing():
                times.append(self._next_probe)
            return max(now, min(times)) if times else None

    def _probing(self) -> bool:
        """Whether this side still probes its peers' clocks: it judges commands' ages and knows
        no peer's offset yet. A probe is a packet with T (and its K), sent alone at start and
        every PROBE_EVERY s, PROBES times at most; a peer whose offset is unknown reports it
        at once (`received`), so both offsets are measured before the first command comes."""
        return (self.clock_exchange and bool(self.max_ages) and self._probes < PROBES
                and not self.offsets.peers())

    # -- receiving ------------------------------------------------------------------------

    def received(self, envelope: env.Envelope, now: float) -> bool:
        """Takes what `envelope` tells (its number, K, T, A). False: a repeat of a packet
        received (counted `duplicate_packets`), of which nothing is taken: not its report, not
        its T as a clock sample (a copy DESERT's MAC sent again left when the first did), and
        its messages are not delivered (the unpacker drops them)."""
        with self._lock:
            peer = envelope.sender
            epoch = self._epoch(envelope)
            # a reliable message, or a command (its sender repairs it from our report: 15.6)
            eliciting = any(m.id in self.heads.numbered and m.kind == 0
                            or m.id in self.engine.told.watched and m.kind in COMMAND_KINDS
                            for m in envelope.messages)
            # the clock exchange (clock_offset.py) completes at once: a packet with T from a
            # peer whose offset is not measured is reported without waiting, and a report
            # with T is answered while we have sent fewer than CLOCK_REPLIES (acks.ReportTimes)
            clock = self.clock_exchange and envelope.time is not None and (
                self.offsets.of(peer) is None
                or envelope.ack is not None and self.report_times.answering())
            if not self.engine.received(peer, epoch, envelope.number, now, eliciting or clock):
                self.counters.inc("duplicate_packets")
                return False
            if clock and not eliciting:
                r = self.engine._current(peer)
                if r is not None and r.eliciting_since is not None:
                    r.eliciting_since = min(r.eliciting_since, now - self.ack_delay)
            self.acks.heard(peer, bool(envelope.messages), now)
            if envelope.ack is None:
                self.silence.heard(peer, epoch, envelope.number, self.settled_by(peer, now), now)
            else:
                self.judge.sample(peer, envelope, self.engine.largest_sent, now)
                before = self.engine.bad_acks
                self.engine.acked(envelope.ack, now, reporter=peer,
                                  settled_by=self.settled_by(peer, now))
                if self.send_epoch is not None and self.engine.largest_acked is not None:
                    self.send_epoch.acked = True
                self.acks.confirm()
                if self.engine.bad_acks > before:
                    log_count(log, logging.WARNING, self.counters.inc("bad_acks"),
                              "[%s] ignored an acknowledgement from %s that is malformed "
                              "or names packets never sent: %s", self.name, self.judge.who(peer),
                              envelope.ack.hex(" "))
            self._rx = (peer, epoch, envelope.time)
            fates = self.engine.told.take()
            if envelope.time is not None:
                for m in envelope.messages:
                    if m.kind == env.FRAGMENT and m.body:
                        # a fragmented message's age item was written with its first fragment:
                        # it is judged by the T of the oldest packet of its transfer seen
                        key = (peer, epoch, m.body[0])
                        first = self._transfer_t.get(key)
                        self._transfer_t[key] = envelope.time if first is None else min(first, envelope.time)
                        while len(self._transfer_t) > TRANSFERS_KEPT:
                            self._transfer_t.popitem(last=False)
        self._tell(fates)
        return True

    def _tell(self, fates: list[tuple[int, bytes, bool]]) -> None:
        """Hand the commands' fates a report told to the bridge (outside the lock: it may
        take a copy back from the link's queue or offer an answer again)."""
        if self.on_fate is None:
            return
        for key, payload, arrived in fates:
            try:
                bare = self.heads.take(payload).payload
            except HeadError:
                continue
            self.on_fate(key, bare, arrived)

    def _epoch(self, envelope: env.Envelope) -> bytes:
        """The sender's epoch (epoch.PeerEpochs), acting on a stand-in named or a restart."""
        epoch, renamed, restarted = self._peers.of(envelope, self.engine.receipts)
        if renamed is not None:
            self.engine.rename_epoch(envelope.sender, renamed, epoch)
            self.acks.rename_epoch(envelope.sender, renamed, epoch)
        if restarted:
            self._restarted(envelope.sender)
        return epoch

    def _restarted(self, peer: int) -> None:
        """`peer` started again: its clock is measured again, it learns our epoch at once (K
        on our next packets), and what it did not get of ours so far is `unknown`."""
        self.counters.inc("restarts_seen")
        log.info("[%s] %s started again (a new epoch): its packets and reliable messages are "
                 "counted afresh; what it had not acknowledged of ours is counted unknown and "
                 "reliable messages are sent again", self.name, self.judge.who(peer))
        self.offsets.forget(peer)
        self.report_times.restarted()
        if self.send_epoch is not None:
            self.send_epoch.peer_restarted()
        self.engine.peer_restarted()

    def admit(self, payload: bytes, now: float, transfer: int | None = None) -> bytes | None:
        """`transfer`: the payload was reassembled from that transfer's fragments."""
        with self._lock:
            try:
                got = self.heads.take(payload)
            except HeadError as e:
                log_count(log, logging.WARNING, self.counters.inc("bad_heads"),
                          "[%s] dropped a message whose reliability head is malformed: %s",
                          self.name, e)
                return None
            ident = env.from_v1(got.payload).id if got.number is not None or got.age is not None else None
            peer, epoch, time24 = self._rx if self._rx is not None else (-1, b"", None)
            if transfer is not None:
                time24 = self._transfer_t.pop((peer, epoch, transfer), time24)
            if got.number is not None and not self.engine.deliver_once(peer, epoch, ident, got.number):
                return None
            if got.age is not None:
                if self.judge.refuses(ident, peer, time24, got.age):
                    return None
                if ident in self._command_ids:         # when its call began (judge.taken)
                    self.judge.taken(got.payload, now)
            return got.payload

    # -- reporting ---------------------------------------------------------------------------

    def ledger(self) -> dict[int, dict[str, int]]:
        """Per channel key: sent = delivered + lost_on_link + in_flight + unacknowledged + unknown
        (copies),
        with resent and expired (reliable entries) and duplicates received."""
        with self._lock:
            flying = self.engine.in_flight()
            out = {k: {**asdict(e), "in_flight": flying.get(k, 0)}
                   for k, e in self.engine.ledger.items() if k != REPORT_KEY}
            for k, n in self.engine.duplicates.items():
                out.setdefault(k, {})["duplicates"] = n
            for k, n in self.stale_by_id.items():
                out.setdefault(k, {})["stale"] = n
            return out

    def stats(self) -> dict:
        ledger = self.ledger()
        with self._lock:
            rtt = self.engine.rtt
            return {"ledger": ledger,
                    "reliability": {**self.counters.as_dict(), "rto": rtt.rto, "srtt": rtt.srtt,
                                    "rtt_samples": rtt.samples,
                                    "spurious_resends": self.engine.spurious,
                                    "fast_resends": self.engine.fast_resends,
                                    "timer_resends": self.engine.timer_resends,
                                    "copies": self.engine.spare.sent,
                                    "report_bytes": self.report_bytes,
                                    "lost_by_silence": self.silence.inferred,
                                    **self.echoes.stats(),
                                    "clock_offsets": {p: o.as_dict() for p, o in
                                                      self.offsets.peers().items()}}}
