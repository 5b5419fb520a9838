"""TDMA bridges timing their writes to their slot (uwgen.runtime.link.mac.TdmaMac) against
the emulator's UW/TDMA (uwgen.emulator.tdma), in simulated time: once a side has heard the
other and settled, what it writes waits in DESERT about one period, not up to a frame, and
DESERT's MAC queue never holds more than a slot's packets."""
from __future__ import annotations

import pytest

from uwgen.emulator import NodeSpec, Scenario, TdmaSpec
from uwgen.emulator.core import EmulatorCore
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.link.mac import Mac, TdmaMac
from uwgen.runtime.link.slot_timing import LEAD

LINK = LinkConfig(max_read_length=64, period=0.2)
STEP = 0.005                  # how often the simulated bridges look at their clocks


def run(config: MacConfig, distance: float, seconds: float, timed: bool = True):
    """Both sides always have a 64-byte packet to write (a saturated link); each writes when
    its pacer (one per period + 5 %) and its MAC allow. Returns (wait in DESERT of each packet
    by side and write time, the emulator's counters). `timed` False: bridges unaware of the
    slot (`Mac`)."""
    sides = config.slots
    senders = {s: i + 1 for i, s in enumerate(sides)}
    scenario = Scenario(nodes=[NodeSpec(s, position=(i * distance, 0.0, 0.0), dest="*")
                               for i, s in enumerate(sides)],
                        period=0.2, max_read_length=64, bitrate=config.bitrate,
                        tdma=TdmaSpec(frame=config.frame, guard=config.guard,
                                      max_packet_per_slot=config.max_packet_per_slot,
                                      queue_size=config.queue_size,
                                      weights=tuple(config.weight(s) for s in sides)))
    core = EmulatorCore(scenario)
    macs = {s: TdmaMac(config, s, LINK, senders=senders) if timed else Mac() for s in sides}
    pace = {s: 0.0 for s in sides}
    waits: dict[str, list[tuple[float, float]]] = {s: [] for s in sides}
    for s in sides:
        core.client_attached(s, 0.0)
    t = 0.0
    while t < seconds:
        for s in sides:
            if t >= pace[s] and macs[s].next_write_at(t) <= t:
                core.client_data(s, t, bytes(64))
                macs[s].wrote(t, 64)
                pace[s] = t + 0.21
        for d in core.advance(t):
            waits[d.source].append((d.queued_at, d.sent_at - d.queued_at))
            macs[d.node].arrived(len(d.data), d.time)
            macs[d.node].heard(senders[d.source], b"", d.time)
        t += STEP
    return waits, core.all_counters()


def most_wait(config: MacConfig, side: str) -> float:
    """The longest a packet written in `side`'s write window can wait in DESERT: from the
    window's first write to the ON window's opening (or a period, the tick, after its write),
    then behind the slot's other packets."""
    mac = TdmaMac(config, side, LINK)
    air = (64 + 4) * 8 / config.bitrate
    return max(mac.timer.open_at - mac.timer.begin, 0.2) + (mac.capacity - 1) * air + 2 * STEP


@pytest.mark.parametrize("guard", [0.25, 0.35])
def test_timed_writes_wait_in_desert_for_their_window_not_a_frame(guard):
    config = MacConfig(mode="tdma", frame=1.0, guard=guard, slots=("surface", "vehicle"),
                       max_packet_per_slot=1000, queue_size=10, range=300)
    waits, counters = run(config, 300.0, 30.0)
    for side, w in waits.items():
        late = [wait for at, wait in w if at > 10.0]         # once each has heard the other and
        assert late and max(late) <= most_wait(config, side) < 0.5, side    # settled
        assert len(late) >= 2 * 19, side                    # the slot's 2 packets every frame
    assert all(c["dropped_queue_full"] == 0 and c["max_mac_queue"] <= 2 for c in counters.values())


def test_writes_unaware_of_the_slot_wait_up_to_a_frame_in_the_same_desert():
    # the reference: bridges writing at their period as under CSMA-ALOHA (`Mac`)
    config = MacConfig(mode="tdma", frame=1.0, guard=0.25, slots=("surface", "vehicle"),
                       max_packet_per_slot=1000, queue_size=10, range=300)
    waits, _ = run(config, 300.0, 30.0, timed=False)
    assert max(wait for w in waits.values() for _, wait in w) > 0.5


def test_a_fleet_slot_fed_ahead_of_its_window_drains_its_capacity_each_frame():
    # the fleet sample: frame 3.7 s, the surface weighted 2 (ON 1.14 s), three vehicles
    # (ON 0.40 s: their 4 packets are written ahead of the window and wait queued for it)
    config = MacConfig(mode="tdma", frame=3.7, guard=0.34, slots=("surface", "auv1", "auv2", "auv3"),
                       max_packet_per_slot=6, queue_size=10, weights=(("surface", 2),),
                       range=300)
    waits, counters = run(config, 100.0, 80.0)
    for side, w in waits.items():
        capacity = TdmaMac(config, side, LINK).capacity
        late = [wait for at, wait in w if at > 40.0]         # heard and settled
        assert late and max(late) <= most_wait(config, side) < 1.0, side
        # every packet is delivered to the 3 other sides; the slot's capacity every frame
        assert len(late) >= 3 * capacity * (40 / 3.7 - 1), side
    assert all(c["max_mac_queue"] <= 6 and c["lost_collision"] == 0 for c in counters.values())
