"""An emulated network from a uwgen manifest: one DESERT node per side.

`uwgen emulate -m uwgen.yaml [scenario.yaml]`: the manifest (validated as every command
validates it) says which nodes exist (its sides, by name), their ports and their link
settings (max_read_length, period); a
scenario file may add the physics (positions, waypoints, SNR model, seed, ...) but
not contradict the manifest. The manifest's `mac:` section picks DESERT's MAC: UW/TDMA with
its frame, slots and guard for mode tdma, stock CSMA-ALOHA otherwise (uwgen.emulator.tdma).
Sides without a position in the scenario are placed on a
line, `spacing` metres apart. With two sides each sends to the other; with more, each
broadcasts (every other node receives what it sends).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from uwgen.emulator.scenario import BROADCAST, NodeSpec, Scenario, ScenarioError, TdmaSpec, load_scenario
from uwgen.idl.model import DefinitionError
from uwgen.manifest.nodes import ManifestError

LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def load_checked(manifest: Path):
    """The manifest, validated as `uwgen build` and `analyze` validate it (its types resolved
    from the interface packages beside it and the installed ones, every entry and id checked,
    each side's max_read_length above the network's floor): the emulator never runs a
    network the bridges would refuse. ManifestError or DefinitionError, located."""
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.linkfloor import check_read_lengths
    from uwgen.manifest.loader import load_manifest
    from uwgen.typesupport import package_dirs

    folder = Path(manifest).parent
    lib = InterfaceLibrary([folder] if package_dirs(folder) else [], installed=True)
    loaded = load_manifest(Path(manifest), lib)
    check_read_lengths(loaded)
    return loaded


def scenario_from_manifest(manifest: Path, physics: Path | None = None,
                           spacing: float = 1000.0) -> Scenario:
    """The scenario of `manifest`'s sides, with the scenario file `physics` laid on top.
    Raises ScenarioError (a bad manifest's ManifestError text is kept, file:line:column)."""
    try:
        checked = load_checked(manifest)
    except (ManifestError, DefinitionError) as exc:
        raise ScenarioError(str(exc)) from None
    sides, mac = checked.sides, checked.mac
    if len(sides) < 2:
        raise ScenarioError(f"the manifest has {len(sides)} side: an emulated network needs "
                            "at least 2", str(manifest))
    for side in sides.values():
        if side.host not in LOCAL_HOSTS:
            where = (f"{side.where.path}:{side.where.line}:{side.where.column}"
                     if side.where else str(manifest))
            raise ScenarioError(f"side {side.name}'s DESERT node is at {side.host}: the "
                                "emulator serves 127.0.0.1 only (use a real DESERT there, or "
                                "host 127.0.0.1)", where)
    dest = None if len(sides) == 2 else BROADCAST
    base = [NodeSpec(side.name, port=side.port, position=(i * spacing, 0.0, 0.0), dest=dest,
                     period=side.link.period, max_read_length=side.link.max_read_length)
            for i, side in enumerate(sides.values())]
    if mac.mode == "tdma":
        base = [replace(n, slot=mac.slot_of(n.name)) for n in base]
    scenario = Scenario(nodes=base) if physics is None else load_scenario(physics, base_nodes=base)
    return with_mac(scenario, mac)


def with_mac(scenario: Scenario, mac) -> Scenario:
    """`scenario` with the channel the manifest's `mac:` section asks DESERT for: UW/TDMA's
    frame, slots, guard, max_packet_per_slot and queue_size for mode tdma; stock CSMA-ALOHA
    for modes none and turns (turn-taking is the bridges'); the MAC's bitrate."""
    if mac.mode == "tdma":
        return replace(scenario, bitrate=mac.bitrate, tdma=TdmaSpec(
            frame=mac.frame, guard=mac.guard, slots=len(mac.slots),
            max_packet_per_slot=mac.max_packet_per_slot, queue_size=mac.queue_size,
            weights=mac.slot_weights() if mac.weights else ()))
    if mac.mode == "turns":
        return replace(scenario, bitrate=mac.bitrate, tdma=None)
    return scenario
