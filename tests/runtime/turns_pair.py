"""Two wire-format-2 links under the turns MAC, 1000 m apart, on a ManualClock (the
emulator's DuplexSim): what tests of commands over turns start from."""
from __future__ import annotations

from collections.abc import Callable

from uwgen.emulator import NodeSpec, Scenario
from uwgen.emulator.duplex import DuplexSim
from uwgen.manifest.model import LinkConfig, MacConfig
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.link.mac import mac_for

TURNS = MacConfig(mode="turns", range=1000.0, leader="surface",
                  packets=(("surface", 4), ("vehicle", 2)), bitrate=4800.0)
SENDERS = {"surface": 1, "vehicle": 2}


class Wall:
    """The wall clock a ManualClock stands for (seconds since 1970)."""

    def __init__(self, clock: ManualClock):
        self.clock = clock

    def now(self) -> float:
        return 1.7e9 + self.clock.now()


def turns_pair(commands: frozenset[int], max_ages: dict[int, float],
               settle: Callable[[Reliability], None]
               ) -> tuple[DuplexSim, ManualClock, dict[str, Reliability]]:
    """The two links (`sim.links[side]`) and each side's reliability, its measured loss set
    by `settle` (a Reliability's `engine.spare.settled` fed as the test wants)."""
    scen = Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(1000, 0, 0), dest="surface")],
                    period=0.2, max_read_length=64, bitrate=4800.0)
    clock = ManualClock()
    macs = {side: mac_for(TURNS, side, SENDERS, LinkConfig(64, 0.2)) for side in SENDERS}
    rel: dict[str, Reliability] = {}

    def hooks_for(side):
        rel[side] = Reliability(SENDERS[side], period=0.2, reliable={}, max_ages=max_ages,
                                wall=Wall(clock), name=side, max_read_length=64,
                                other_overhead=macs[side].overhead, turn_gap=macs[side].turn_gap(),
                                settled_by=macs[side].settled_by, unheard=macs[side].unheard,
                                commands=commands,
                                own_span=macs[side].own_span())
        settle(rel[side])
        return rel[side].hooks()
    sim = DuplexSim(scen, ("surface", "vehicle"), hooks_for=hooks_for, wire_format=2,
                    clock=clock, step=0.025,
                    link_kw_for=lambda side: {"mac": macs[side], "sender_id": SENDERS[side]})
    return sim, clock, rel
