"""PacketSeal: the per-packet seal of wire format 2 links (docs/wire-format.md section 12.2,
docs/seams.md sections 2 and 5).

`hooks()` gives the `PacketHooks` a Link takes (joined with reliability's by the bridge):

- sending, at the moment the packer builds a packet: `next_overhead(now)` plans it (a sync
  packet or not, a sync request or not), `number()` takes its number from this side's epoch
  (`epochs.SendSession`: random epoch per start, numbers counted in memory), `parts(now)` gives
  K (epoch, number bits 12-43) and T (this side's wall clock) on sync packets and C (a sync
  request) when one is due, `seal(envelope)` computes the one tag (`packetwire.seal`), of the
  link's `config.tag_bytes` (4, 6 or 8; the manifest's `security: {tag_bytes}`).
  Sync packets: the first `SYNC_FIRST` of an epoch, every `SYNC_EVERY`-th, the first after
  `SYNC_PERIOD` s without one, the next `SYNC_FIRST` after a peer's new epoch, the next
  `SYNC_ANSWER` after a peer asked for one, and every packet that asks one;
- receiving: `open(bytes)` decodes the envelope, refuses what is not sealed by a peer, checks a
  T it carries (`_time_ok`: against the max age of its messages, or, once the link's
  reliability judges each command's age and gives this seal its peers' measured clock offsets
  (`use_offsets`), against the link's default max age with the offset taken off), and hands
  the rest to
  `receiver.Receiver.admit` (epoch, freshness, tag, replay window), so only admitted envelopes
  reach the link (and reliability's `received`). Every drop is counted by reason and logged
  throttled (`droplog.DropLog`); a packet dropped `unsynced` makes this side ask its sender for
  a sync in its next packet (C part, `control.py`), at most once per `ASK_GAP` s per peer, and
  a peer's request is answered at most once per `ASK_GAP` s: a request never makes a packet of
  its own, it only adds K and T (13 bytes) to the next `SYNC_ANSWER` packets. A sync packet
  that fails its tag but verifies at another tag length comes from a peer built with another
  `tag_bytes`: dropped as `tag_length`, and an error says so once per peer (`taglength.py`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

from uwgen.runtime.wire import envelope as env
from uwgen.runtime.clock import SYSTEM_CLOCK, WALL_CLOCK, Clock
from uwgen.runtime.delivery.freshness import sent_at, stamp
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.stats import log_count
from uwgen.security import control, packetwire, taglength, wire
from uwgen.security.clock_notes import ClockNotes
from uwgen.security.droplog import SUMMARY_PERIOD, log
from uwgen.security.epochs import EPOCH_NUMBERS
from uwgen.security.errors import SecurityError
from uwgen.security.files import SideLock
from uwgen.security.side import SideSeal
from uwgen.runtime.delivery.epoch import SYNC_BYTES, on_schedule
from uwgen.security.guard import DROP_REASONS, GuardConfig
from uwgen.security.keys import new_epoch, working_key
from uwgen.security.receiver import Numbering
from uwgen.security.window import WINDOW

COUNTERS = ("protected", "sync_sent", "verified", "epochs_seen", "asks_sent", "asks_answered",
            "asks_ignored", "unknown_control", *DROP_REASONS)
SYNC_ANSWER = 2            # sync packets sent to answer a peer's request
ASK_GAP = 5.0              # seconds between two requests to (or answers for) one peer
ASK_BEFORE = 2.0           # seconds: a packet refused before_start this near our start asks a sync
NUMBER_BITS = 12           # W carries the packet number's low 12 bits
ASK_BYTES = 2              # a C part of one item: its length byte and the item


def max_overhead(tag_bytes: int = env.TAG_LEN) -> int:
    """The most bytes the seal adds to a packet: the tag, K and T, and a C of one request."""
    return tag_bytes + SYNC_BYTES + ASK_BYTES


MAX_OVERHEAD = max_overhead()      # 23, with the default 8-byte tag


@dataclass(frozen=True)
class _Plan:
    seq: int                 # the number the plan is for
    sync: bool
    ask: int | None          # the peer asked for a sync in this packet


class PacketSeal(SideSeal):
    COUNTERS = COUNTERS

    def __init__(self, master: bytes, config: GuardConfig, *, fragment_id: int | None = None,
                 clock: Clock = SYSTEM_CLOCK, wall: Clock = WALL_CLOCK, name: str = "link",
                 window: int = WINDOW, lock: SideLock | None = None, epoch_source=new_epoch,
                 epoch_numbers: int = EPOCH_NUMBERS, summary_period: float = SUMMARY_PERIOD):
        if epoch_numbers <= 0 or epoch_numbers % env.NUMBER_MOD:
            raise SecurityError(f"an epoch of {epoch_numbers} packets: a multiple of "
                                f"{env.NUMBER_MOD} (W's numbers) is needed")
        super().__init__(master, config, clock=clock, wall=wall, name=name, window=window,
                         lock=lock, epoch_source=epoch_source, epoch_numbers=epoch_numbers,
                         summary_period=summary_period, reentrant=True)
        self.fragment_id = fragment_id
        self._encrypt_any = wire.ENCRYPT in config.modes.values()
        self._plan: _Plan | None = None
        self._current: tuple[int, bytes, object] | None = None    # (seq, epoch, aead) being built
        self.requests = control.SyncRequests(ASK_GAP)
        self._told_length: set[int] = set()     # peers whose other tag length was logged
        self.clock_notes = ClockNotes(name, config.peers, self.freshness, self.wall)
        self._offset_of = None                  # sender -> measured clock offset (use_offsets)

    def use_offsets(self, offset_of) -> None:
        """`offset_of(sender)`: that peer's clock offset measured by the link's reliability
        (`clock_offset.Offset`, or None), which also judges every message with a max age
        (docs/wire-format.md section 15.5). From then on T is checked with the offset taken
        off, against the link's default max age (docs/security.md, "Clocks")."""
        with self._lock:
            self._offset_of = offset_of

    def hooks(self) -> PacketHooks:
        return PacketHooks(parts=self.parts, seal=self.seal, open=self.open,
                           overhead=max_overhead(self.config.tag_bytes),
                           next_overhead=self.next_overhead,
                           number=self.number)

    def _encrypts(self, m: env.Message) -> bool:
        """Whether message `m`'s body is encrypted: its id is `encrypt`, or it is a fragment and
        the network encrypts any id (what a fragment carries is known only once reassembled)."""
        if env.is_fragment_message(m, self.fragment_id):
            return self._encrypt_any
        return self.config.modes.get(m.id) == wire.ENCRYPT

    def _fingerprint(self, ident: int) -> bytes:
        return self.config.fingerprints.get(ident, b"")

    # -- sending -----------------------------------------------------------------------

    def _decide(self, now: float, seq: int) -> _Plan:
        ask = self.requests.next()
        sync = on_schedule(seq, now, self._last_sync) or self._sync_due > 0 or ask is not None
        return _Plan(seq, sync, ask)

    def next_overhead(self, now: float) -> int:
        """Bytes the seal adds to the next packet (planned now, kept for it)."""
        with self._lock:
            s = self.session
            seq = 0 if s.next >= s.limit else s.next
            self._plan = plan = self._decide(now, seq)
            return (self.config.tag_bytes + (SYNC_BYTES if plan.sync else 0)
                    + (ASK_BYTES if plan.ask is not None else 0))

    def number(self) -> int:
        """The packet's number: its number in this side's epoch, plus the numbers of the epochs
        before (monotonic for reliability; the low 12 bits are the same, epochs being a
        multiple of 4096 numbers long)."""
        with self._lock:
            s = self.session
            seq = s.take()
            self._current = (seq, s.epoch, s.aead)
            return (s.epochs_started - 1) * s.limit + seq

    def parts(self, now: float) -> dict:
        with self._lock:
            if self._current is None:
                raise env.EnvelopeError("the seal gives parts only to a packet it numbered")
            seq, epoch, _ = self._current
            plan = self._plan if self._plan is not None and self._plan.seq == seq else self._decide(now, seq)
            self._plan = None
            out: dict = {}
            if plan.sync:
                self._last_sync = now
                self._sync_due = max(0, self._sync_due - 1)
                out["sync"] = env.Sync(epoch, seq >> NUMBER_BITS)
                out["time"] = stamp(self.wall.now())
            if plan.ask is not None:
                self.requests.asked(plan.ask, now)
                self.counters.inc("asks_sent")
                out["control"] = control.sync_request(plan.ask)
            return out

    def seal(self, envelope: env.Envelope) -> bytes:
        with self._lock:
            if self._current is None:
                raise env.EnvelopeError("the seal seals only a packet it numbered")
            seq, _, aead = self._current
            self._current = None
            data = packetwire.seal(aead, envelope, seq, self._encrypts, self._fingerprint)
            self.counters.inc("protected")
            if envelope.sync is not None:
                self.counters.inc("sync_sent")
            return data

    # -- receiving ---------------------------------------------------------------------

    def open(self, data: bytes) -> env.Envelope | None:
        """The envelope (encrypted bodies in the clear), or None when dropped (counted).
        EnvelopeError for bytes that are no envelope (counted by the link's unpacker)."""
        e = env.decode(data, self.config.tag_bytes)
        with self._lock:
            return self._open(e, bytes(data))

    def _open(self, e: env.Envelope, data: bytes) -> env.Envelope | None:
        drop = self.drops.drop
        if not e.sealed:
            return drop("unprotected", None, e.sender)
        if e.sender == self.config.sender:
            return drop("reflected", None, e.sender)
        if e.sender not in self.config.peers:
            return drop("unknown_sender", None, e.sender)
        if e.sync is not None and e.time is None:
            return drop("malformed", None, e.sender)
        max_age = self._max_age(e.messages)
        numbering = Numbering(e.sender, e.number, NUMBER_BITS,
                              None if e.sync is None else (e.sync.high << NUMBER_BITS) | e.number,
                              None if e.sync is None else wire.Sync(e.sync.epoch, e.time))

        def verify(aead, seq: int):
            return packetwire.open_envelope(aead, e, seq, self._encrypts, self._fingerprint)
        if e.time is not None and not self._time_ok(e, max_age):
            # refused for its time before its tag is checked; what is said of the sender's
            # clock is said of its own packets only (a forgery must not use that line up)
            if not self.receiver.authentic(numbering, verify):
                return drop("bad_tag", None, e.sender)
            self.clock_notes.time_refused(e)
            return drop("stale", None, e.sender)
        got = self.receiver.admit(numbering, max_age, verify, time_checked=True)
        if isinstance(got, str):
            if got == "stale" and e.sync is not None:
                self.clock_notes.time_refused(e)
            if got == "before_start":
                self.clock_notes.before_start(e)
            if got == "unsynced" or got == "before_start" and self._nearly_started(e.time):
                self.requests.want(e.sender, self.clock.now())
            if got == "bad_tag" and e.sync is not None and self._other_length(data, e.sender):
                got = "tag_length"
            return drop(got, None, e.sender)
        self.counters.inc("verified")
        self.requests.heard(e.sender)
        if got.control:
            self._control(got)
        return got

    def _nearly_started(self, time24: int) -> bool:
        """Whether a packet refused `before_start` was stamped under `ASK_BEFORE` s before our
        start (a peer whose clock is behind looks so until it passes our start): its answer to
        a sync request, sealed a round trip later, then passes (the clock exchange needs it)."""
        return self.receiver.started - sent_at(time24, self.wall.now()) < ASK_BEFORE

    def _offset(self, sender: int):
        """The sender's measured offset when it is known well enough to judge T by (its error
        within the tolerance), else None."""
        o = self._offset_of(sender) if self._offset_of is not None else None
        return o if o is not None and o.error <= self.freshness.tolerance else None

    def _max_age(self, messages) -> float:
        """The max age T is checked against: the strictest of the packet's messages; with the
        link's reliability judging each message's own (`use_offsets`), the link's default."""
        if self._offset_of is not None:
            return self.config.max_age
        ages = self.config.max_ages
        return min((ages.get(m.id, self.config.max_age) for m in messages),
                   default=self.config.max_age)

    def _time_ok(self, e: env.Envelope, max_age: float) -> bool:
        """Whether the packet's T is fresh: sealed at most `max_age` plus the tolerance ago.
        With the sender's offset measured, T is read on our clock (the offset taken off); with
        the link's reliability judging commands, T may be ahead by up to the link's default
        max age, measured or not, so a peer whose clock is ahead, or was stepped ahead, is
        heard and measured (holding a packet makes T older, and T is under the tag). Never more than `max_age` plus the
        tolerance old, whatever the offset."""
        o = self._offset(e.sender)
        wall = self.wall.now() + (o.offset if o is not None else 0.0)
        age = self.freshness.age(e.time, wall)
        # judged by reliability (`use_offsets`), measured or not: a clock stepped ahead after
        # it was measured is heard and measured again, never locked out
        ahead = (self.freshness.tolerance if self._offset_of is None
                 else max(self.freshness.tolerance, self.config.max_age))
        return -ahead <= age <= max_age + self.freshness.tolerance

    def _other_length(self, data: bytes, sender: int) -> bool:
        """Whether sync packet `data` verifies at another tag length (logged once per peer)."""
        def aead_for(s: int, epoch: bytes, length: int):
            return wire.new_aead(working_key(self._master, self.config.network, s, epoch), length)
        length = taglength.other_length(data, self.config.tag_bytes, aead_for, self._encrypts,
                                        self._fingerprint)
        if length is not None and sender not in self._told_length:
            self._told_length.add(sender)
            log.error("[%s] sender %d (%s) seals its packets with %d-byte tags, this side expects "
                      "%d bytes (manifest security: tag_bytes): the two sides were built from "
                      "different manifests, and nothing of that sender is taken. Build both from "
                      "one manifest", self.name, sender, self.config.peers.get(sender, "?"),
                      length, self.config.tag_bytes)
        return length is not None

    def _control(self, e: env.Envelope) -> None:
        now = self.clock.now()
        for item in control.items(e.control):
            if item.code in control.MAC_CODES:
                continue                     # the link's MAC reads them (hooks.received)
            if item.code != control.SYNC_REQUEST:
                log_count(log, logging.WARNING, self.counters.inc("unknown_control"),
                          "[%s] sender %d's packet has a control item of code %d this build does "
                          "not know: ignored", self.name, e.sender, item.code)
            elif item.sender == self.config.sender:
                if self.requests.answer(e.sender, now):
                    self._sync_due = max(self._sync_due, SYNC_ANSWER)
                    self.counters.inc("asks_answered")
                else:
                    self.counters.inc("asks_ignored")

    # -- accounting and shutdown -------------------------------------------------------

    def stats(self) -> dict:
        with self._lock:
            return {**self._side_stats(), "per_packet": True}
