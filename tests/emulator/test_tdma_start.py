"""TDMA bridges (uwgen.runtime.link.mac.TdmaMac) from their first packet, against the
emulator's UW/TDMA (uwgen.emulator.tdma), in simulated time: the demo's TDMA (frame 1 s, 2
slots, guard 0.25 s, 300 m, 64 B at 4800 bit/s: a packet and the range take 0.31 s, more
than the guard), both sides saturated, started at every phase of the frame, restarted, or
started late: no packet is lost to a collision between the two sides, and a side that
starts late or restarts finds its slot. With a guard that covers a packet and the range
(the benchmarks' TDMA: frame 3 s, guard 0.8 s, 1000 m: 0.78 s) every side writes at once at
start, so a first packet lost costs a frame, not the wait for the next blind write."""
from __future__ import annotations

import pytest

from uwgen.emulator import NodeSpec, Scenario, TdmaSpec
from uwgen.emulator.core import EmulatorCore
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac import TdmaMac
from uwgen.runtime.link.slot_timing import blind_frames

LINK = LinkConfig(max_read_length=64, period=0.2)
DEMO = MacConfig(mode="tdma", frame=1.0, guard=0.25, slots=("surface", "vehicle"),
                 max_packet_per_slot=1000, queue_size=10, range=300)
# benchmarks/commands_sim.py's TDMA: a packet started anywhere in ON ends before the next slot
BENCH = MacConfig(mode="tdma", frame=3.0, guard=0.8, slots=("surface", "vehicle"),
                  max_packet_per_slot=1000, queue_size=10, bitrate=4800, range=1000)
SENDERS = {"surface": 1, "vehicle": 2}
STEP = 0.005                  # how often the simulated bridges look at their clocks


def run(starts: dict[str, float], seconds: float, ticks: tuple[float, float] = (0.0, 0.0),
        restart: tuple[str, float] | None = None, per: float = 0.0, seed: int = 1,
        config: MacConfig = DEMO, lost_first: tuple[str, ...] = ()):
    """Each side from its start on always has a 64-byte packet to write and writes when its
    pacer (one per period + 5 %) and its MAC allow; `ticks`: each DESERT node's period tick
    phase; `restart`: (side, when) its bridge starts again knowing nothing; `lost_first`: these
    sides' first packets never reach DESERT (lost as if on the channel). Returns (the
    emulator's counters, delivery times by sending side, the MACs)."""
    scenario = Scenario(nodes=[NodeSpec(s, position=(i * config.range, 0.0, 0.0), phase=ticks[i])
                               for i, s in enumerate(config.slots)],
                        period=0.2, max_read_length=64, bitrate=config.bitrate, per=per, seed=seed,
                        tdma=TdmaSpec(frame=config.frame, guard=config.guard,
                                      max_packet_per_slot=1000, queue_size=10))
    core = EmulatorCore(scenario)
    macs = {s: TdmaMac(config, s, LINK, senders=SENDERS) for s in config.slots}
    losing = set(lost_first)
    pace = {s: 0.0 for s in config.slots}
    delivered: dict[str, list[float]] = {s: [] for s in config.slots}
    for s in config.slots:
        core.client_attached(s, 0.0)
    k = 0
    while (t := k * STEP) < seconds:
        if restart is not None and k == round(restart[1] / STEP):
            macs[restart[0]] = TdmaMac(config, restart[0], LINK, senders=SENDERS)
        for s in config.slots:
            if t >= max(starts[s], pace[s]) and macs[s].next_write_at(t) <= t:
                if s in losing:
                    losing.discard(s)
                else:
                    core.client_data(s, t, bytes(64))
                macs[s].wrote(t, 64)
                pace[s] = t + 0.21
        for d in core.advance(t):
            delivered[d.source].append(d.time)
            macs[d.node].arrived(len(d.data), d.time)
            macs[d.node].heard(SENDERS[d.source], b"", d.time)
        k += 1
    return core.all_counters(), delivered, macs


def collisions(counters: dict) -> int:
    return sum(c["lost_collision"] for c in counters.values())


@pytest.mark.parametrize("ticks", [(0.0, 0.0), (0.0, 0.1)])
def test_no_start_phase_loses_a_packet_to_a_collision(ticks):
    # a packet DESERT starts late in the surface's ON window (its period tick 0.2 s into the
    # frame) runs 0.06 s into the vehicle's slot: had it been written before the surface
    # knew the frame's phase while the vehicle sent at its slot's start, one was lost
    lost = {}
    for s in range(10):
        for v in (0.0, 0.3, 0.6):
            counters, delivered, _ = run({"surface": 5.0 + s / 10, "vehicle": 5.0 + v}, 15.0, ticks)
            lost[(s / 10, v)] = collisions(counters)
            assert delivered["surface"] and delivered["vehicle"]
    assert sum(lost.values()) == 0, {k: n for k, n in lost.items() if n}


@pytest.mark.parametrize("side", ["surface", "vehicle"])
def test_a_side_that_restarts_finds_its_slot_without_a_collision(side):
    for when in (12.0, 12.25, 12.5, 12.75):
        counters, delivered, macs = run({"surface": 0.0, "vehicle": 0.0}, 25.0, restart=(side, when))
        assert collisions(counters) == 0, when
        # it heard the other side's timed packets before it wrote: nothing written blind
        assert macs[side].stats()["blind_writes"] == 0, when
        assert any(when < t < when + 4.0 for t in delivered[side]), when


def test_a_side_that_starts_late_hears_its_way_into_its_slot():
    counters, delivered, macs = run({"surface": 0.0, "vehicle": 20.0}, 30.0, per=0.2, seed=3)
    assert collisions(counters) == 0
    assert macs["vehicle"].stats()["blind_writes"] == 0
    assert min(delivered["vehicle"]) < 20.0 + 3.0


@pytest.mark.parametrize("lost", [(), ("surface",), ("vehicle",)])
def test_with_a_guard_covering_a_packet_both_sides_speak_in_the_first_frame(lost):
    # the first slot's side used to listen two frames and then write one packet per four:
    # its first packet lost, the other side heard nothing for 18 s. Now each side writes at
    # once; one first packet lost, the other's still teaches the phase, and every start
    # phase keeps both sides' packets apart
    frame = BENCH.frame
    for k in range(6):
        start = 5.0 + k * frame / 6
        counters, delivered, macs = run({"surface": start, "vehicle": start + 0.1}, start + 4 * frame,
                                        config=BENCH, lost_first=lost)
        assert collisions(counters) == 0, start
        heard = {s: min(delivered[s], default=None) for s in BENCH.slots}
        for side in BENCH.slots:
            # a frame to the side's ON window, a second frame when the other's first was lost
            # (the phase it then learns, unsettled, times its packets to the next frame)
            assert heard[side] is not None and heard[side] < start + 3 * frame, (start, side, heard)
        if not lost:
            assert max(heard.values()) < start + 2 * frame, (start, heard)


def test_with_both_first_packets_lost_the_sides_hear_each_other_after_the_next_blind_write():
    # each side's next blind write goes blind_frames (3) frames after its first: a frame
    # sooner than four, and the settling rule still tells blind packets from timed ones
    frame = BENCH.frame
    assert blind_frames(BENCH, LINK) == 3
    for k in range(6):
        start = 5.0 + k * frame / 6
        counters, delivered, macs = run({"surface": start, "vehicle": start + 0.1}, start + 6 * frame,
                                        config=BENCH, lost_first=("surface", "vehicle"))
        assert collisions(counters) == 0, start
        heard = {s: min(delivered[s], default=None) for s in BENCH.slots}
        # the second blind write, a period to DESERT, up to a frame to its ON window, air and range
        assert all(h is not None and h < start + 5 * frame for h in heard.values()), (start, heard)
        assert all(m.stats()["blind_writes"] == 2 for m in macs.values()), start


@pytest.mark.parametrize("side", ["surface", "vehicle"])
def test_with_a_guard_covering_a_packet_a_side_that_restarts_writes_at_once_without_a_collision(side):
    # its blind packet, started anywhere in its ON window, ends before the other's slot:
    # the other side's timed packets are never met, and the side finds its slot within two frames
    frame = BENCH.frame
    for k in range(4):
        when = 30.0 + k * frame / 4
        counters, delivered, macs = run({"surface": 0.0, "vehicle": 0.0}, when + 4 * frame,
                                        config=BENCH, restart=(side, when))
        assert collisions(counters) == 0, when
        assert macs[side].stats()["blind_writes"] <= 1, when      # none when it heard first
        assert any(when < t < when + 2 * frame for t in delivered[side]), when
