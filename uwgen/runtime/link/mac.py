"""When this side may write: the link's MAC (docs/seams.md section 7; docs/emulator.md, MACs).

Sans-IO: every call carries `now` (the link's clock). The connection writes when both its
`Pacer` (DESERT's one packet per period) and the `Mac` allow it: `next_write_at(now)`
(-inf: now, inf: not until something is heard), then `wrote(now, nbytes)` for each write.
The packer asks `hooks()` for the C items of each packet (`control`), for an empty packet
that must leave (`ack_only`: a grant or an end of turn) and tells it every admitted
envelope (`received` -> `heard`). `turn_gap()` is the longest a reply waits for the peer's
turn: delivery's retransmission timer starts no lower than a round trip plus it.

- `Mac` (mode `none`): always allows; DESERT's own MAC decides (stock CSMA-ALOHA: packets of
  two sides may collide).
- `TdmaMac`: DESERT runs UW/TDMA. It writes at most the packets its slot drains per frame
  (`tdma_capacity`), so DESERT's queues never hold more than a slot's worth. It learns the
  frame's phase from the packets it hears and writes each frame's packets so that they reach
  DESERT's MAC just before its ON window opens (uwgen.runtime.link.slot_timing): a message
  then waits in DESERT about one period, not up to a frame (until the phase is settled:
  before the slot opens even if the phase is late). With no phase (nothing heard
  in `MEMORY_FRAMES` frames) it writes one packet every few frames, at once when the guard
  covers a packet and the range (`blind_safe`), else after listening: DESERT may start it
  late in the window, and such a guard is what keeps it out of the next slot.
- `TurnMac` (mode `turns`): the leader grants the turn to one side at a time (C item 2, to
  whom and how many packets); that side writes after hearing the grant, at most that many
  packets, the last carrying C item 3 (end of turn), all inside a window from the grant;
  the leader takes the turn back when it hears the end, or when the last packet of that
  window could no longer start arriving (uwgen.runtime.link.turn_timing: bounds from the
  manifest's physics, moved to the rest of the answer by each packet heard): the miss is
  counted and the next side is granted, so a lost grant or answer costs the wait for what
  could still come, and a side that starts late or restarts answers the next grant naming
  it. The packet before a full turn's last gives notice of the grant (`2S 00`): a follower
  that heard it and lost the grant takes its turn all the same once the grant's packet has
  ended. Needs no change inside DESERT and no clock agreement: every timer starts from an
  event this side saw.
  `settled_by` tells delivery that a peer's answer was built after all of this side's packets
  of the turn before it had arrived or been lost (a report there names their loss at once);
  `unheard` that the leader took a follower's turn back unheard, so that its next packet
  carries that report even with no news.
"""
from __future__ import annotations

import math
from collections.abc import Callable

from uwgen.manifest.mac import LISTEN
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.link.mac_items import (TURN_END, TURN_GRANT, MacItem,  # noqa: F401 (the MAC's names)
                                          decode_items, encode_items)
from uwgen.runtime.link.pacing import DEFAULT_MARGIN
from uwgen.runtime.link.slot_timing import FramePhase, SlotTimer, tdma_capacity
from uwgen.runtime.link.turn_timing import REACT, RoundTrip, TurnTiming
from uwgen.runtime.wire import envelope as env

INF = math.inf


class Mac:
    """Mode `none`: DESERT's MAC decides; this side writes whenever its pacer allows."""

    mode = "none"
    overhead = 0                         # most bytes the MAC adds to a packet (C part included)
    burst = 0.0                          # s between write windows: rate limits hold over it

    def __init__(self):
        self.backlog: Callable[[float], bool] = lambda now: False   # set by the Link
        self.carries = False             # the packet being built carries messages

    def next_write_at(self, now: float) -> float:
        return -INF

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

    def turn_gap(self) -> float:
        return 0.0

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


class TdmaMac(Mac):
    """DESERT's UW/TDMA underneath (module doc). `senders`: side -> sender id, for every side
    (the frame's phase is learned from what they send); `anonymous`: packets carry no sender
    (wire format 1), so a packet heard comes from the only other side, if there is one."""

    mode = "tdma"

    def __init__(self, config: MacConfig, side: str, link: LinkConfig,
                 margin: float = DEFAULT_MARGIN, senders: dict[str, int] | None = None,
                 anonymous: bool = False):
        super().__init__()
        self.config, self.side = config, side
        self.burst = config.frame            # one write window a frame
        self.capacity = tdma_capacity(config, link, side)
        self.max_bytes = link.max_read_length
        ids = {s: i for s, i in (senders or {}).items() if s in config.slots}
        self.phase = FramePhase(config, {i: config.slot_start(s) for s, i in ids.items()}, link)
        others = [i for s, i in ids.items() if s != side]
        self._anonymous = others[0] if anonymous and len(others) == 1 else None
        self.timer = SlotTimer(config, side, link, self.capacity, link.period * (1.0 + margin))
        self._arrived: tuple[int, float] | None = None     # the packet being opened: (bytes, when)

    def next_write_at(self, now: float) -> float:
        return self.timer.next_write_at(self.phase.start(now), now, self.phase.settled(now))

    def wrote(self, now: float, nbytes: int) -> None:
        self.timer.wrote(self.phase.start(now), now)

    def arrived(self, nbytes: int | None, now: float) -> None:
        size = self.max_bytes if nbytes is None else nbytes
        if self._anonymous is not None:
            self.phase.heard(self._anonymous, size, now)
        else:
            self._arrived = (size, now)

    def heard(self, sender: int, control: bytes, now: float) -> None:
        size, at = self._arrived if self._arrived is not None else (self.max_bytes, now)
        self._arrived = None
        self.phase.heard(sender, size, at)

    def hooks(self) -> PacketHooks | None:
        return PacketHooks(received=self._received)

    def turn_gap(self) -> float:
        return self.config.frame

    def own_span(self) -> float:
        return self.config.slot_length(self.side)

    def stats(self) -> dict:
        return {"mode": self.mode, "capacity_per_frame": self.capacity, "timed_writes": self.timer.timed,
                "blind_writes": self.timer.blind}


class TurnMac(Mac):
    """Mode `turns` (module doc). `senders`: side name -> sender id, for every side."""

    mode = "turns"
    overhead = 3        # the C part's length byte and a grant (2 bytes) or an end (1 byte)

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
        taken back at (the manifest's range or bitrate is not the real one): later grants
        to it wait that much longer (counted `late_answers`)."""
        if self._missed is None or sender != self._missed[0]:
            return
        _who, deadline, span = self._missed
        if not deadline < start < deadline + span:
            return
        self.counts["late_answers"] += 1
        self._late[sender] = max(self._late[sender], start - deadline + LISTEN)

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


def mac_for(config: MacConfig | None, side: str, senders: dict[str, int],
            link: LinkConfig, wire_format: int = 2) -> Mac:
    """The Mac of `side` under the manifest's `mac:` section (None: mode none)."""
    if config is None or config.mode == "none":
        return Mac()
    if config.mode == "tdma":
        return TdmaMac(config, side, link, senders=senders, anonymous=wire_format != 2)
    if wire_format != 2:
        raise ValueError(f"mac mode turns needs an envelope link, wire format {env.VERSION} (its grants are C items)")
    return TurnMac(config, side, senders, link)
