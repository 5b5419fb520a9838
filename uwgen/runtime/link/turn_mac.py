"""Mode `turns`: the leader grants the turn to one side at a time (uwgen.runtime.link.mac,
module doc; docs/wire-format.md section 16)."""
from __future__ import annotations

from uwgen.manifest.mac import LISTEN
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac_base import INF, Mac
from uwgen.runtime.link.mac_items import TURN_END, TURN_GRANT, MacItem, decode_items, encode_items
from uwgen.runtime.link.pacing import DEFAULT_MARGIN
from uwgen.runtime.link.turn_timing import REACT, RoundTrip, TurnTiming, late_by


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
        # a turn's round trip besides its packets until measured: two trips, ticks and listens
        self.rtt = {sid: RoundTrip(2 * self.timing.one_way) for sid, _ in self.followers}
        self._late = {sid: 0.0 for sid, _ in self.followers}   # learned: answers later than the bound
        self._next = 0                    # index of the follower granted next
        self._holding = self.leading      # leader: its own turn; follower: a turn granted
        self._granted, self._sent = (self.my_packets if self.leading else 0), 0
        self._closing: MacItem | None = None    # the item the packet being built ends with
        self._built = -INF                # the last packet's build time, as delivery dates it
        self._noticing = False            # leader: the packet being built gives notice
        self._noticed_at: float | None = None   # leader: when the notice of the next grant left
        self._waiting: tuple[int, int, float, float] | None = None   # (sender, n, at, deadline)
        self._missed: tuple[int, float, float] | None = None   # leader: (who, deadline, span), last missed
        self._unheard: dict[int, float] = {}   # leader: follower -> when its turn was last taken back
        self._earliest = -INF             # leader: no answer to its grant starts arriving before
        self._heard_in_wait = 0
        self._size: int | None = None     # bytes of the packet being opened (arrived)
        self._turn_until = INF            # follower: no packet of its turn is written after it
        self._notice_at = INF             # follower: its turn starts then if the grant is lost
        self._by_notice = False           # follower: took that turn; the grant is answered
        self._last_end: float | None = None   # follower: when it last wrote its turn's end
        self.counts = {k: 0 for k in ("turns", "grants_sent", "grants_heard", "ends_heard",
                                      "missed", "recovered", "dropped_turns", "not_mine",
                                      "notices_heard", "turns_from_notice", "late_answers", "late_grants")}

    # -- when ----------------------------------------------------------------------------

    def next_write_at(self, now: float) -> float:
        self._expire(now)
        if self._holding:
            return -INF
        if self._waiting is not None:
            return self._waiting[3]
        return self._notice_at

    def must_send(self, now: float) -> bool:
        self._expire(now)
        return self._holding

    def next_time(self, now: float) -> float | None:
        self._expire(now)
        if self._holding:
            return now
        if self._waiting is not None:
            return self._waiting[3]
        return self._notice_at if self._notice_at < INF else None

    def _expire(self, now: float) -> None:
        if self._waiting is not None and now >= self._waiting[3]:
            self.counts["missed"] += 1          # the grant or the end was lost: take it back
            who, _n, at, deadline = self._waiting
            self._missed = (who, deadline, deadline - at)
            self._unheard[who] = now
            self._waiting = None
            self._own_turn()
        noticed = self._noticed_at if self.leading and self._holding else None
        if noticed is not None and now > noticed + self.interval + REACT:   # a stalled thread:
            self.counts["late_grants"] += 1   # the grant would meet the notice's turn (rule 1)
            self._granted_by(*self.followers[self._next % len(self.followers)], noticed, noticed)
        if not self.leading and self._holding and now > self._turn_until:
            self.counts["dropped_turns"] += 1   # too late to use it: the leader has moved on
            self._holding = False
        if now >= self._notice_at:
            # the notice was heard and the grant it announced lost: the turn is ours all the
            # same, for the manifest's count, once the leader's last packet has ended
            self.counts["turns_from_notice"] += 1
            self._take_turn(self.my_packets, self._notice_at, by_notice=True)

    def _own_turn(self) -> None:
        self._holding, self._granted, self._sent = True, self.my_packets, 0

    # -- what each packet carries ---------------------------------------------------------

    def parts(self, now: float) -> bytes:
        if not self._holding:
            return b""
        self._sent += 1
        self._built = now
        # The leader keeps its turn while its packets carry messages (a command stream
        # offered at the link's pace fills it); a follower while more is queued and its
        # window leaves room for another packet.
        more = (self.carries if self.leading
                else self.backlog(now) and now + self.interval <= self._turn_until)
        noticed = self.leading and self._noticed_at is not None   # this packet grants
        if self.leading and self.followers and not noticed and self._sent < self._granted \
                and (not more or self._sent == self._granted - 1):
            # the next packet is the last (this one carries nothing, or the count is reached
            # after it): tell its follower now, so one lost packet does not lose the
            # follower's whole turn (rule 1, the notice); the next packet grants
            sid, _ = self.followers[self._next % len(self.followers)]
            self._closing = None
            self._noticing = True
            return encode_items([MacItem(TURN_GRANT, sid, 0)])
        if self._sent < self._granted and more and not noticed:
            self._closing = None
            return b""
        if self.leading:
            if not self.followers:
                self._closing = None
                return b""
            sid, n = self.followers[self._next % len(self.followers)]
            self._closing = MacItem(TURN_GRANT, sid, n)
        else:
            self._closing = MacItem(TURN_END, self.me)
        return encode_items([self._closing])

    def wrote(self, now: float, nbytes: int) -> None:
        closing, self._closing = self._closing, None
        noticing, self._noticing = self._noticing, False
        if closing is None:
            self._noticed_at = now if noticing else None
            return
        self._holding = False
        built = max(now, self._built)     # `now` came before the build: delivery dates by the build
        if closing.code == TURN_GRANT:
            self.counts["grants_sent"] += 1
            # the grant ends before an answer to it can start (the range: the farthest apart)
            self._granted_by(closing.sender, closing.count, built, now + self.timing.packet_air(nbytes))
        else:
            self.counts["turns"] += 1
            self._last_end = built

    def arrived(self, nbytes: int | None, now: float) -> None:
        self._size = nbytes

    def heard(self, sender: int, control: bytes, now: float) -> None:
        items = decode_items(control) if control else []
        size, self._size = self._size, None
        if self.leading:
            start = now - self.timing.packet_air(size)      # it started arriving then
            if self._waiting is None or sender != self._waiting[0] or start < self._earliest:
                self._heard_late(sender, start)     # not an answer to the grant
                return
            self._heard_in_wait += 1
            who, n, at, deadline = self._waiting
            # It is answering: the rest of its turn has started arriving within its remaining
            # packets' intervals, whatever the first bound said: later (a late answer is
            # never talked over) or sooner (a lost end costs a packet's interval and DESERT's
            # tick, not a whole timeout).
            rest = max(0, n - self._heard_in_wait)
            self._waiting = (who, n, at, self.timing.rest_deadline(start, rest))
            if any(i.code == TURN_END and i.sender == sender for i in items):
                self.counts["ends_heard"] += 1
                self.rtt[who].sample(max(0.0, now - at - (self._heard_in_wait - 1) * self.interval))
                self._waiting = None
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
            if item.count == 0:                 # a notice: the grant comes on the next packet
                if item.sender == self.me and not self._holding:
                    self.counts["notices_heard"] += 1
                    self._notice_at = self.timing.notice_start(now)
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

    def _heard_late(self, sender: int, start: float) -> None:
        """Leader: a follower's packet that started arriving after the bound its turn was
        taken back at (`late_by`): later grants to it wait that much longer (`late_answers`)."""
        by = late_by(self._missed, sender, start)
        if by is not None:
            self.counts["late_answers"] += 1
            self._late[sender] = max(self._late[sender], by + LISTEN)

    def abandoned(self) -> None:
        self._closing, self._noticing = None, False

    def _granted_by(self, sid: int, count: int, at: float, earliest: float) -> None:
        """Wait for follower `sid`'s `count` packets, its turn given at `at` (grant or notice)."""
        deadline = self.timing.grant_deadline(at, count, self._noticed_at) + self._late[sid]
        self._holding, self._next, self._earliest = False, self._next + 1, earliest
        self._waiting, self._noticed_at, self._heard_in_wait = (sid, count, at, deadline), None, 0

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

    def own_span(self) -> float:
        # its packets, one an interval, and the notice's packet before a leader's grant
        return (self.my_packets + self.leading) * self.interval

    def settled_by(self, sender: int, now: float) -> float | None:
        """The leader: a follower answers in the turn granted by its last packet, so
        everything written until the grant was heard or lost before the answer was built. A
        follower: the leader writes again only after its end (or the leader's timer: after a
        round trip), so everything it wrote until the end."""
        if self.leading:
            waiting = self._waiting
            return waiting[2] if waiting is not None and sender == waiting[0] else None
        return self._last_end if sender == self.leader_id and not self._holding else None

    def unheard(self, sender: int) -> float | None:
        """The leader: when it last took `sender`'s turn back on its timer (its end unheard:
        its last packets, an answer or a result among them, were lost; the leader's next report
        settles them). A follower never waits: the leader's lost packets show as a gap."""
        return self._unheard.get(sender)

    def stats(self) -> dict:
        out = {"mode": self.mode, "leader": self.leading, **self.counts}
        if self.leading:
            out["turn_rtt"] = {sid: round(r.srtt, 3) for sid, r in self.rtt.items()}
        return out
