"""Mode `turns`: the leader grants the turn to one side at a time (uwgen.runtime.link.mac,
module doc; docs/wire-format.md section 16)."""
from __future__ import annotations

from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac_base import INF, Mac
from uwgen.runtime.link.mac_items import TURN_END, TURN_GRANT, MacItem, decode_items, encode_items
from uwgen.runtime.link.pacing import DEFAULT_MARGIN
from uwgen.runtime.link.turn_timing import NOTICES, REACT, Rounds, TurnTiming
from uwgen.runtime.link.turn_wait import TurnWait
from uwgen.runtime.wire.codec import KIND_REQUEST


class TurnMac(Mac):
    """Mode `turns` (module doc). `senders`: side name -> sender id, for every side."""

    mode = "turns"
    overhead = 3        # the C part's length byte and a grant (2 bytes) or an end (1 byte)
    late_collides = True    # a grant or an end written late meets the next turn

    def __init__(self, config: MacConfig, side: str, senders: dict[str, int], link: LinkConfig,
                 margin: float = DEFAULT_MARGIN):
        super().__init__()
        self.config = config
        self.me = senders[side]
        self.leader_id = senders[config.leader]
        self.leading = side == config.leader
        self.my_packets = config.turn_packets(side)
        self.timing = TurnTiming(config, link, margin)
        self.air, self.period, self.interval = self.timing.air, link.period, self.timing.interval
        self.followers = [(senders[s], config.turn_packets(s)) for s in senders if s != config.leader]
        self._next = 0                    # index of the follower granted next
        self._holding = self.leading      # leader: its own turn; follower: a turn granted
        self._granted, self._sent = (self.my_packets if self.leading else 0), 0
        self._closing: MacItem | None = None    # the item the packet being built ends with
        self._built = -INF                # the last packet's build time, as delivery dates it
        self._grant_on: int | None = None   # leader: the packet of its turn that grants (notices before)
        self._noticed_at: float | None = None   # leader: when its last notice of the next grant left
        self._grant_by = INF              # leader: no grant is written after it (its notices' promise)
        self._size: int | None = None     # bytes of the packet being opened (arrived)
        self._turn_until = INF            # follower: no packet of its turn is written after it
        self._notice_at = INF             # follower: its turn starts then if the grant is lost
        self._by_notice = False           # follower: took that turn; the grant is answered
        self._last_end: float | None = None   # follower: when it last wrote its turn's end
        self._asked_at: float | None = None   # follower: when the leader's last request (kind 2) came
        self.counts = {k: 0 for k in ("turns", "grants_sent", "grants_heard", "ends_heard",
                                      "missed", "recovered", "dropped_turns", "not_mine",
                                      "notices_heard", "turns_from_notice", "late_answers", "late_grants")}
        self.wait = TurnWait(self.timing, [sid for sid, _ in self.followers], self.counts)
        self.rtt = self.wait.rtt          # the leader's measured turn round trips (a round's size)
        self.rounds = Rounds()            # the spacing of this side's own turns, measured

    # -- when ----------------------------------------------------------------------------

    def next_write_at(self, now: float) -> float:
        self._expire(now)
        if self._holding:
            return -INF
        waiting = self.wait.deadline()
        return waiting if waiting is not None else self._notice_at

    def must_send(self, now: float) -> bool:
        self._expire(now)
        return self._holding

    def next_time(self, now: float) -> float | None:
        at = self.next_write_at(now)
        return None if at == INF else max(at, now)

    def _expire(self, now: float) -> None:
        if self.wait.expired(now):              # the grant or the end was lost: take it back
            self._own_turn()
        if self.leading and self._holding and now > self._grant_by:   # a stalled thread: the
            self.counts["late_grants"] += 1   # grant would meet the notices' turn (rule 1)
            self._granted_by(*self.followers[self._next % len(self.followers)],
                             self._noticed_at, self._noticed_at)
        if not self.leading and self._holding and now > self._turn_until:
            self.counts["dropped_turns"] += 1   # too late to use it: the leader has moved on
            self._holding = False
        if now >= self._notice_at:
            # a notice was heard and the grant it announced lost: the turn is ours all the
            # same, for the manifest's count, once the leader's last packet has ended
            self.counts["turns_from_notice"] += 1
            self._take_turn(self.my_packets, self._notice_at, by_notice=True)

    def _own_turn(self) -> None:
        self._holding, self._granted, self._sent = True, self.my_packets, 0
        self._grant_on, self._noticed_at, self._grant_by = None, None, INF

    # -- what each packet carries ---------------------------------------------------------

    def parts(self, now: float) -> bytes:
        self._closing = None
        if not self._holding:
            return b""
        self._sent += 1
        self._built = now
        if self._sent == 1:
            self.rounds.started(now)
        if self.leading:
            return self._leader_parts(now)
        # a follower keeps its turn while more is queued and its window leaves room for
        # another packet; its first packet does not end it while a request heard since its
        # last turn has had no answer offered after it (rule 2: the answer is on its way)
        answering = self._sent == 1 and self._asked_at is not None and self.answered_at < self._asked_at
        if self._sent < self._granted and (self.backlog(now) or answering) \
                and now + self.interval <= self._turn_until:
            return b""
        self._closing = MacItem(TURN_END, self.me)
        return encode_items([self._closing])

    def _leader_parts(self, now: float) -> bytes:
        """Rule 1: once the turn starts ending (`_ends_here`), NOTICES packets give notice of
        the grant (fewer when the count leaves less room), the next grants."""
        if not self.followers:
            return b""
        if self._grant_on is None and self._ends_here(now):
            self._grant_on = min(self._sent + NOTICES, self._granted)
        if self._grant_on is None:
            return b""
        sid, n = self.followers[self._next % len(self.followers)]
        if self._sent >= self._grant_on:
            self._closing = MacItem(TURN_GRANT, sid, n)
            return encode_items([self._closing])
        return encode_items([MacItem(TURN_GRANT, sid, 0)])

    def _ends_here(self, now: float) -> bool:
        """Leader: whether its turn starts ending on this packet. It keeps the turn while its
        packets carry messages and more waits or came lately (a stream offered at the link's
        pace fills it); it ends when the count leaves room for only the notices and the
        grant, on a packet that carries nothing, or on one after which nothing waits and
        nothing was offered for an interval (sparse commands: no packet spent waiting)."""
        return (self._sent >= self._granted - NOTICES or not self.carries
                or (not self.backlog(now) and now - self.offered_at >= self.interval))

    def wrote(self, now: float, nbytes: int) -> None:
        closing, self._closing = self._closing, None
        if closing is None:
            if self._grant_on is not None and self._sent < self._grant_on:   # a notice:
                # the grant leaves at most that many intervals and REACT after it, or not at
                # all (a follower that heard it starts from it then: rule 1)
                self._noticed_at = now
                self._grant_by = min(self._grant_by,
                                     now + (self._grant_on - self._sent) * self.interval + REACT)
            return
        self._holding = False
        built = max(now, self._built)     # `now` came before the build: delivery dates by the build
        if closing.code == TURN_GRANT:
            self.counts["grants_sent"] += 1
            # the grant ends before an answer to it can start (the range: the farthest apart)
            self._granted_by(closing.sender, closing.count, built, now + self.timing.packet_air(nbytes))
        else:
            self.counts["turns"] += 1
            self._last_end, self._asked_at = built, None

    def arrived(self, nbytes: int | None, now: float) -> None:
        self._size = nbytes

    def _received(self, envelope, now: float) -> None:
        if not self.leading and envelope.sender == self.leader_id \
                and any(m.kind == KIND_REQUEST for m in envelope.messages):
            self._asked_at = now
        super()._received(envelope, now)

    def heard(self, sender: int, control: bytes, now: float) -> None:
        items = decode_items(control) if control else []
        size, self._size = self._size, None
        if self.leading:
            # it started arriving then
            if self.wait.heard(sender, items, now - self.timing.packet_air(size), now):
                self._own_turn()
            return
        if sender != self.leader_id:
            return
        # the grant after a notice whose turn this side took (the leader's DESERT sent it
        # late) is answered: a second turn would meet the leader's, taken back at our end
        answered, self._by_notice = self._by_notice, False
        for item in items:
            if item.code != TURN_GRANT:
                continue
            if answered and item.sender == self.me and item.count:
                self.counts["late_grants"] += 1   # a follower's: heard after its notice's turn
                continue
            if item.count == 0:                 # a notice: the grant comes within NOTICES packets
                if item.sender == self.me and not self._holding:
                    self.counts["notices_heard"] += 1
                    # one heard before it (its grant not yet): this is the last, the grant is next
                    distance = 1 if self._notice_at < INF else NOTICES
                    self._notice_at = min(self._notice_at, self.timing.notice_start(now, distance))
                continue
            self._notice_at = INF
            if item.sender != self.me:
                self.counts["not_mine"] += 1
                self._holding = False
                continue
            self.counts["grants_heard"] += 1
            if self._holding:
                self.counts["recovered"] += 1
            self._take_turn(item.count, now)

    def abandoned(self) -> None:
        self._closing = None

    def _granted_by(self, sid: int, count: int, at: float, earliest: float) -> None:
        """Wait for follower `sid`'s `count` packets, its turn given at `at` (grant or notice)."""
        self.wait.start(sid, count, at, earliest, self._noticed_at)
        self._holding, self._next = False, self._next + 1
        self._grant_on, self._noticed_at, self._grant_by = None, None, INF

    def _take_turn(self, count: int, now: float, by_notice: bool = False) -> None:
        self._notice_at, self._by_notice = INF, by_notice
        self._holding, self._granted, self._sent = True, count, 0
        # its packets are written inside the window the leader's bound counts on: a turn not
        # used by then is gone (a side that comes back late never talks over the next turn)
        self._turn_until = self.timing.window(now, count)

    # -- for delivery and status ----------------------------------------------------------

    def cycle(self) -> float:
        """Seconds of one round of turns: the leader's and every follower's (measured turn
        round trips on the leader, the first guess on a follower)."""
        return (self.config.turn_packets(self.config.leader) * self.interval
                + sum(n * self.interval + self.rtt[sid].srtt for sid, n in self.followers))

    def turn_gap(self) -> float:
        return self.cycle()

    def round(self) -> float:
        measured = self.rounds.measured()
        return self.cycle() if measured is None else measured

    def next_turn(self, now: float) -> float:
        return now if self._holding else self.rounds.next_start(now, self.round())

    def own_span(self) -> float:
        # its packets, one an interval, and on the leader one more (a margin)
        return (self.my_packets + self.leading) * self.interval

    def settled_by(self, sender: int, now: float) -> float | None:
        """The leader: a follower answers in the turn granted by its last packet, so
        everything written until the grant was heard or lost before the answer was built. A
        follower: the leader writes again only after its end (or the leader's timer: after a
        round trip), so everything it wrote until the end."""
        if self.leading:
            return self.wait.settled_by(sender)
        return self._last_end if sender == self.leader_id and not self._holding else None

    def reports_twice(self) -> bool:
        return self.leading          # its notices and grant follow its first packet (rule 1)

    def unheard(self, sender: int) -> float | None:
        """The leader: when it last took `sender`'s turn back on its timer (its end unheard:
        its last packets, an answer or a result among them, were lost; the leader's next report
        settles them). A follower never waits: the leader's lost packets show as a gap."""
        return self.wait.unheard(sender)

    def stats(self) -> dict:
        out = {"mode": self.mode, "leader": self.leading, **self.counts}
        if self.leading:
            out["turn_rtt"] = {sid: round(r.srtt, 3) for sid, r in self.rtt.items()}
        return out
