"""When this side may write: the link's MAC (docs/seams.md section 7; docs/emulator.md, MACs).

The interface the connection and the packer use, and mode `none`, are in
uwgen.runtime.link.mac_base; `TurnMac` is in uwgen.runtime.link.turn_mac. Here: `TdmaMac`,
and `mac_for`, which builds a side's MAC from the manifest.

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
  it. The two packets before the grant give notice of it (`2S 00`): a follower that heard
  one and lost the grant takes its turn all the same once the grant's packet has ended. Needs no change inside DESERT and no clock agreement: every timer starts from an
  event this side saw.
  `settled_by` tells delivery that a peer's answer was built after all of this side's packets
  of the turn before it had arrived or been lost (a report there names their loss at once);
  `unheard` that the leader took a follower's turn back unheard, so that its next packet
  carries that report even with no news; `reports_twice` that the leader says a report
  telling a loss once more on its next packet (a notice or the grant, leaving anyway).
"""
from __future__ import annotations

from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.hooks import PacketHooks
from uwgen.runtime.link.mac_base import INF, Mac  # noqa: F401 (the MAC's names)
from uwgen.runtime.link.mac_items import (TURN_END, TURN_GRANT, MacItem,  # noqa: F401
                                          decode_items, encode_items)
from uwgen.runtime.link.pacing import DEFAULT_MARGIN
from uwgen.runtime.link.slot_timing import FramePhase, SlotTimer, tdma_capacity  # noqa: F401
from uwgen.runtime.link.turn_mac import TurnMac
from uwgen.runtime.wire import envelope as env


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
