"""A faithful emulator of DESERT UW/APPLICATION sockets and the acoustic channel between them.

    from uwgen.emulator import Scenario, NodeSpec, run_emulator
    scen = Scenario(nodes=[NodeSpec("surface", position=(0, 0, 0), dest="vehicle"),
                           NodeSpec("vehicle", position=(300, 0, 0), dest="surface")],
                    period=0.2, max_read_length=64, bitrate=4800, per=0.0, seed=1)
    with run_emulator(scen) as emu:
        emu.port("vehicle"); emu.counters("vehicle"); emu.restart(); emu.stop()

The model itself is `EmulatorCore` (sans-IO, driven by explicit times); `Emulator` runs it
behind real TCP sockets; `SnrModel` is the UW/PHYSICAL-like channel; `pdr_sweep` the
delivery-ratio-against-distance study. See docs/emulator.md.
"""
from uwgen.emulator.core import LOSS_CAUSES, Delivery, EmulatorCore
from uwgen.emulator.physics import SnrModel
from uwgen.emulator.scenario import (BROADCAST, MAX_READ_LENGTH_LIMIT, NodeSpec, Scenario, ScenarioError,
                                     TdmaSpec, load_scenario)
from uwgen.emulator.server import Emulator, EmulatorError, run_emulator
from uwgen.emulator.sweep import SweepPoint, pdr_sweep

__all__ = [
    "BROADCAST", "Delivery", "Emulator", "EmulatorCore", "EmulatorError", "LOSS_CAUSES",
    "MAX_READ_LENGTH_LIMIT", "NodeSpec", "Scenario", "ScenarioError", "SnrModel", "SweepPoint",
    "TdmaSpec", "load_scenario", "pdr_sweep", "run_emulator",
]
