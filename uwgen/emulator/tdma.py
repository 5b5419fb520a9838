"""UW/TDMA as DESERT runs it (DESERT_Framework/DESERT/data_link/uwtdma/uwtdma.cpp), for the
emulator's core (uwgen.emulator.core): pure functions of the scenario's `TdmaSpec`.

- Fair mode: slot = frame / slots; a node is ON for slot - guard from its slot's start
  (`slot_number * slot`, from the node's start), OFF for the rest of the frame: the guard is
  a silent tail at the end of the node's own slot. Manual mode (`weights`): slot k starts
  after the slots before it and lasts its weight's share of the frame (each node's
  setStartTime and setSlotDuration), the same otherwise.
- A packet may START anywhere in the ON window and ends when its air time ends, past the
  window if it must (DESERT never checks that it fits): a guard shorter than a packet's air
  time plus the propagation delay lets it run into the next node's slot.
- At most `max_packet_per_slot` packets start in one window, one after the other (the next
  starts when the previous ends, while the window is open).
- The MAC queue holds `queue_size` packets: a packet arriving from uwApplication when it is
  full is dropped (DESERT's default, `drop_old_ 0`), which DESERT does not count; the
  emulator counts it (`dropped_queue_full`).
"""
from __future__ import annotations

import math

from uwgen.emulator.scenario import TdmaSpec
from uwgen.emulator.slots import bounds


def next_start(tdma: TdmaSpec, slots: int, slot: int, origin: float, t: float,
               counted_frame: int, sent: int) -> tuple[float, int]:
    """(earliest time >= t a packet may start in the node's ON window, that window's frame
    index). `counted_frame`, `sent`: the window the node last sent in and how many it started
    there (max_packet_per_slot)."""
    start, slot_len = bounds(tdma, slots, slot)
    on = slot_len - tdma.guard
    k = math.floor((t - origin - start) / tdma.frame)
    while True:
        open_at = origin + k * tdma.frame + start
        close_at = open_at + on
        full = k == counted_frame and sent >= tdma.max_packet_per_slot
        if t < close_at - 1e-12 and not full:
            return max(t, open_at), k
        k += 1


def queue_full(tdma: TdmaSpec, queued: int) -> bool:
    """Whether DESERT's MAC queue refuses a new packet (queue_size_, drop the new one)."""
    return queued >= tdma.queue_size
