"""When a TDMA side's writes must reach DESERT (docs/seams.md section 7; docs/emulator.md,
MACs): the frame's phase learned from packets heard, and the write window of this side's slot.
Sans-IO: every call carries `now` (the link's clock).

DESERT's UW/TDMA shares no clock with the bridge, but its schedule shows in what the bridge
hears: a packet from side S reaches the bridge at

    frame start + S's slot start + its place in S's ON window + air time + propagation

and the manifest gives every slot's start, the air time (its bytes and `bitrate`) and the
longest propagation (`range`). `FramePhase` takes each heard packet's frame start assuming
it left first in its window over the whole range: late by its place in the window, early by
at most `range - distance` over the speed of sound, so over recent packets the earliest
estimate is the frame's start, or a little before it (packets then wait that much longer in
DESERT, they never miss the window). The estimates of a frame lie
within one ON window plus that error, less than a frame, so the earliest is the one after
the largest gap between them around the circle of the frame. Packets older than `memory`
are forgotten: a side that has heard nothing for that long knows no phase.

`SlotTimer` places this side's writes for its slot: from `open` (the slot's start) to
`close`, the end of its send window (`send_window`: a packet started later would reach the
far side after the next slot has begun). DESERT's uwApplication moves one packet from the
socket to the MAC per `period`, a write waiting up to a period for that tick, and the link
writes one packet per `interval` (its pacer). The window's writes start at `open - period -
lead`, so the first packet waits in the MAC queue only for the slot to open and the others
join it one tick after they are written, or earlier when the slot's `capacity` packets
written one interval apart would not all reach the MAC `lead` before `close`, with `lead`
to spare for a late thread (they then wait queued for the slot, at most `capacity` of
them). Writes end at `close - lead - period`: a later one could miss the window and wait a
whole frame. Every packet is built as it is written, so it is the freshest it can be. A
frame's writes are counted from the end of the window before (also those made while no
phase was known), so whatever DESERT's queue held drains before more is written.

Settling: a packet heard may have started anywhere in its sender's ON window (its sender
wrote it before knowing the phase), so a phase learned from such packets may be late by up
to the longest other ON window. Until the phase is *settled*, the write windows end that
much earlier: every packet then reaches the MAC before the slot opens, whatever the error,
and starts at the opening, so the other sides hear the exact phase. The windows begin as
late as the slot's packets allow, and after this slot's window before closed (a packet
reaching the MAC earlier would go in that one, maybe late in it). The phase is settled
once two packets of one sender were heard less than `pair_gap` apart, within `memory`: one
of them was timed (it started at its window's opening, settling or settled, and its estimate
is exact). A side with no phase writes one packet per `blind_frames` frames, B; DESERT starts
each from at once to a period plus a frame less its ON window after its write, and their air
times differ by less than a full packet's, so two blind packets arrive at least

    pair_gap = (B - 1) * frame - period - air - LEAD

apart (`LEAD` for the writing thread's lateness). Timed packets may come one a frame, so
the gap must exceed a frame and a packet's air time: B is the least from its floor that
makes it (the floor whenever the frame is longer than a period, two packets' air time and
`LEAD`). The floor is `BLIND_FRAMES` (3) where a blind packet cannot meet another side's
(`blind_safe`), `UNSAFE_BLIND_FRAMES` (4) where it may run into the next slot: there each one
risks the packet of a side that has just begun to answer the one before, and the answer
may take more than three frames (the blind packet starts up to a period and a frame after
its write, the answer up to a frame and a period after it was heard, each then crosses the
range). The period and packet size are this side's: the sides' DESERT nodes share them. A
peer whose node ticks slower could have two blind packets taken as a pair, and this side's
writes then placed up to an ON window late: where the guard covers a packet that only delays
them, where it does not they could run into the next slot, so there the gap is at most
`B - 2` frames (a frame and more to spare for the slower tick).

No phase known (start, restart, or nothing heard for `memory`): DESERT may start a packet
written now anywhere in the ON window. When the guard covers a packet's air time and the
range's delay (`blind_safe`), a packet started anywhere in ON reaches every side before the
next slot begins, so a packet written blind can meet no other side's: the side writes at
once, whichever its slot (at a common start every side's first packet leaves in the first
frame, and one of them lost still leaves the others to teach the phase and carry T for the
clock exchange, docs/wire-format.md section 15.5). When the guard is shorter, a packet
started late in ON runs into the next slot and loses itself or the next side's first
packet. So the side listens first, `LISTEN_FRAMES` frames if its slot is the frame's first,
`MEMORY_FRAMES` otherwise (a side that starts late or restarts hears the others' timed
packets and never writes blind; at a common start the first slot's side speaks first while
the others, silent until they hear, leave the slot it may run into empty). Either way it
then writes one packet per `blind_frames` frames: time for the others to hear it and for
their timed packets to come back, so another one goes blind only when all of those were
lost (when not `blind_safe`, it may then run into a slot the others use); the settling rule
above counts on that spacing.
"""
from __future__ import annotations

import math
from collections import deque

from uwgen.manifest.mac import air_time
from uwgen.manifest.model import LinkConfig, MacConfig

LEAD = 0.05           # s: writes reach DESERT's MAC this long before they must (clock and thread jitter)
MEMORY_FRAMES = 10    # frames after which a heard packet no longer counts
BLIND_FRAMES = 3      # the fewest frames between two writes made while no phase is known
UNSAFE_BLIND_FRAMES = 4   # ... when such a write may run into the next slot (not blind_safe)
LISTEN_FRAMES = 2     # frames the side of the first slot listens before it writes without a phase
KEEP = 64             # the most recent packets the phase is taken from


def blind_frames(config: MacConfig, link: LinkConfig) -> int:
    """Frames between two writes made while no phase is known: the fewest from
    `BLIND_FRAMES` (`UNSAFE_BLIND_FRAMES` when not `blind_safe`) whose `pair_gap` exceeds a
    frame and a packet's air time (module doc)."""
    frames = BLIND_FRAMES if blind_safe(config, link) else UNSAFE_BLIND_FRAMES
    timed = config.frame + air_time(link.max_read_length, config.bitrate)   # timed ones' least gap
    while pair_gap(config, link, frames) <= timed:
        frames += 1
    return frames


def pair_gap(config: MacConfig, link: LinkConfig, frames: int | None = None) -> float:
    """Two packets of one sender heard less than this apart: one of them was timed (module
    doc: blind packets, written `frames` frames apart, arrive no closer)."""
    frames = blind_frames(config, link) if frames is None else frames
    gap = (frames - 1) * config.frame - link.period - air_time(link.max_read_length, config.bitrate) - LEAD
    return gap if blind_safe(config, link) else min(gap, (frames - 2) * config.frame)


class FramePhase:
    """The start of DESERT's TDMA frame in the link's clock, from packets heard (module doc).
    `slot_starts`: sender id -> seconds from the frame's start to its slot's start."""

    def __init__(self, config: MacConfig, slot_starts: dict[int, float], link: LinkConfig,
                 memory: float | None = None):
        self.frame = config.frame
        self.bitrate = config.bitrate
        self.delay = config.delay                   # propagation over the whole range
        self.slot_starts = dict(slot_starts)
        self.memory = memory if memory is not None else MEMORY_FRAMES * config.frame
        self._heard: deque[tuple[float, float]] = deque(maxlen=KEEP)   # (when heard, estimate)
        self.ignored = 0                            # packets from a sender without a slot
        # two packets of one sender heard this close: one was timed (blind ones are further apart)
        self.pair_gap = pair_gap(config, link)
        self._last: dict[int, float] = {}           # sender -> when its last packet was heard
        self._timed_at = -math.inf                  # when a packet known timed was heard

    def heard(self, sender: int, nbytes: int, now: float) -> None:
        """A packet of `nbytes` (as DESERT sent it, before its header) from `sender` arrived now."""
        start = self.slot_starts.get(sender)
        if start is None:
            self.ignored += 1
            return
        air = air_time(nbytes, self.bitrate)
        self._heard.append((now, (now - air - self.delay - start) % self.frame))
        if now - self._last.get(sender, -math.inf) < self.pair_gap:
            self._timed_at = now
        self._last[sender] = now

    def settled(self, now: float) -> bool:
        """Whether a packet its sender timed to its slot is among those the phase is taken
        from: the phase is then exact, not late by a packet's place in its window."""
        return self._timed_at >= now - self.memory

    def start(self, now: float) -> float | None:
        """A time (mod `frame`, in [0, frame)) at which a frame starts; None when nothing was
        heard in the last `memory` seconds."""
        while self._heard and self._heard[0][0] < now - self.memory:
            self._heard.popleft()
        if not self._heard:
            return None
        marks = sorted(r for _, r in self._heard)
        # the earliest: the mark after the largest gap around the frame's circle
        gaps = [(marks[0] + self.frame - marks[-1], 0)]
        gaps += [(marks[i] - marks[i - 1], i) for i in range(1, len(marks))]
        return marks[max(gaps)[1]]


class SlotTimer:
    """When `side` may write (module doc): while the frame's start is not known (`origin`
    None), after listening and then one write per `blind_gap`; else in its slot's write
    windows (the settling ones while the phase is new), at most `capacity` writes since the
    window before ended (a write made before the phase was known counts: its packet may
    still wait)."""

    def __init__(self, config: MacConfig, side: str, link: LinkConfig, capacity: int,
                 interval: float, lead: float = LEAD):
        self.frame, self.capacity, self.lead = config.frame, capacity, lead
        self.open_at = config.slot_start(side)              # from the frame's start
        on = config.slot_length(side) - config.guard
        close = self.open_at + send_window(config, link, side)
        self.end = close - lead - link.period               # last write of a frame's window
        first = min(self.open_at - link.period - lead, self.end - (capacity - 1) * interval - lead)
        self.begin = max(first, self.end - self.frame + 1e-6)   # windows never overlap
        # settling: a packet heard may have started anywhere in its sender's ON window, so
        # the phase may be late by that much; every write then reaches the MAC before the
        # slot opens all the same, as late as the slot's packets allow, and after this slot's
        # window before closed
        late = max((config.slot_length(s) - config.guard for s in config.slots if s != side),
                   default=0.0)
        settle_end = self.open_at - late - lead - link.period
        settle_begin = max(self.open_at - self.frame + on,
                           settle_end - (capacity - 1) * interval - lead)
        self.settling = (settle_begin, settle_end) if settle_end > settle_begin else None
        # no phase: listen first only when a packet started late in ON may run into the next
        # slot (module doc)
        self.listen = (0.0 if blind_safe(config, link) else
                       self.frame * (LISTEN_FRAMES if self.open_at == 0 else MEMORY_FRAMES))
        self.blind_gap = blind_frames(config, link) * self.frame
        self._writes: deque[float] = deque()
        self._knew = False                      # a phase was known at the last call
        self._blind_since: float | None = None  # when this side last had no phase
        self._last_blind = -math.inf
        self.timed = 0                          # writes placed in a window
        self.blind = 0                          # writes made with no phase known

    def next_write_at(self, origin: float | None, now: float, settled: bool = True) -> float:
        """-inf: now; else when this side may write next. `settled`: the phase `origin` is
        exact (FramePhase.settled); else the settling windows are used."""
        while self._writes and self._writes[0] + self.frame <= now:
            self._writes.popleft()
        if origin is None:
            if self._blind_since is None:
                # a phase forgotten was heard of last `memory` ago: listened long enough
                self._blind_since = now - self.listen if self._knew else now
            self._knew = False
            at = max(self._blind_since + self.listen, self._last_blind + self.blind_gap)
            return -math.inf if at <= now else at
        self._blind_since, self._knew = None, True
        begin, end = self.writes_window(origin, now, settled)
        if sum(1 for w in self._writes if w > end - self.frame) >= self.capacity:
            begin += self.frame
        return -math.inf if begin <= now else begin

    def wrote(self, origin: float | None, now: float) -> None:
        self._writes.append(now)
        if origin is None:
            self.blind += 1
            self._last_blind = now
        else:
            self.timed += 1

    def writes_window(self, origin: float, now: float, settled: bool = True) -> tuple[float, float]:
        """(begin, end) of the first write window that ends after `now` (a settling one
        unless `settled`)."""
        first, last = (self.settling if self.settling is not None and not settled
                       else (self.begin, self.end))
        base = origin + last
        end = base + ((now - base) // self.frame + 1) * self.frame
        return end - (last - first), end


def send_window(config: MacConfig, link: LinkConfig, side: str | None = None) -> float:
    """Seconds from the start of `side`'s slot (None: the shortest slot) in which a packet
    may start and still reach every side before the next slot begins: DESERT starts one
    anywhere in ON (slot - guard) and lets it run past, so a guard shorter than a packet's
    air time plus the range's delay leaves only slot - air - delay; 0 when not even that
    (the slot's first packet then runs over; `uwgen analyze` warns)."""
    slot = config.slot if side is None else config.slot_length(side)
    return max(0.0, min(slot - config.guard, slot - overrun(config, link)))


def overrun(config: MacConfig, link: LinkConfig) -> float:
    """How long past its start a full packet of `link` is still arriving somewhere: its air
    time and the range's delay (a packet DESERT starts at the end of ON runs that far)."""
    return air_time(link.max_read_length, config.bitrate) + config.delay


def blind_safe(config: MacConfig, link: LinkConfig) -> bool:
    """Whether a packet DESERT starts anywhere in a slot's ON window reaches every side
    before the next slot begins (the guard covers its `overrun`): written with no phase
    known, it can meet no other side's packet."""
    return config.guard >= overrun(config, link)


def tdma_capacity(config: MacConfig, link: LinkConfig, side: str | None = None) -> int:
    """Packets `side`'s slot drains per frame (None: the shortest slot's): DESERT starts
    them one after the other from the window's opening, each in the send window (while
    `max_packet_per_slot` allows), and uwApplication feeds its MAC one packet per `period`;
    at least one."""
    air = air_time(link.max_read_length, config.bitrate)
    by_window = math.floor(send_window(config, link, side) / air) + 1
    by_period = max(1, math.floor(config.frame / link.period))
    return max(1, min(config.max_packet_per_slot, by_window, by_period, config.queue_size))
