"""UW/TDMA's slots in a frame (uwgen.emulator.tdma): equal in DESERT's fair mode, or in
proportion to per-slot `weights` in its manual mode (each node's setStartTime and
setSlotDuration: slot k starts after the slots before it). Takes any object with `frame`,
`guard` and `weights` (the scenario's TdmaSpec)."""
from __future__ import annotations


def check_slots(tdma, slots: int, bad) -> None:
    """`bad(message)` unless `weights` is empty or one positive integer per slot and every
    slot leaves an ON window."""
    weights = tuple(tdma.weights)
    if weights and (len(weights) != slots or not all(
            isinstance(w, int) and not isinstance(w, bool) and w >= 1 for w in weights)):
        bad(f"tdma.weights must be {slots} positive integers (one per slot), got {tdma.weights!r}")
    slot_len = min(bounds(tdma, slots, k)[1] for k in range(slots))
    if slot_len - tdma.guard <= 0:
        bad(f"tdma guard {tdma.guard:g} s leaves no ON window in a {slot_len:g} s slot: "
            "no node could ever send")


def bounds(tdma, slots: int, slot: int) -> tuple[float, float]:
    """(start from the frame's start, length) of slot `slot` of `slots`, in seconds."""
    weights = tuple(tdma.weights) or (1,) * slots
    unit = tdma.frame / sum(weights)
    return unit * sum(weights[:slot]), unit * weights[slot]
