"""Many nodes: a 16-node fleet on TDMA, unicast reports and broadcast orders."""
from __future__ import annotations

from dataclasses import replace

import pytest

from uwgen.emulator import BROADCAST, EmulatorCore, NodeSpec, Scenario, load_scenario

from .helpers import SCENARIOS

FLEET = SCENARIOS / "fleet-16.yaml"


def test_the_fleet_scenario_has_16_nodes_one_slot_each_and_a_guard_over_the_longest_delay():
    scen = load_scenario(FLEET)
    names = scen.names()
    assert len(names) == 16 and names[0] == "surface"
    assert sorted(scen.slot_of(n) for n in names) == list(range(16))
    longest = max(scen.distance(a, b) for a in names for b in names if a != b)
    assert longest / scen.sound_speed < scen.tdma.guard
    assert scen.dest_of("surface") == BROADCAST
    assert {scen.dest_of(n) for n in names[1:]} == {"surface"}


def test_a_loaded_fleet_exchanges_reports_and_orders_without_a_collision():
    scen = load_scenario(FLEET)
    core = EmulatorCore(scen)
    names = scen.names()
    for n in names:
        core.client_attached(n, 0.0)
    frames = 5
    for k in range(frames):                      # one report per vehicle and one order per frame
        t = k * scen.tdma.frame + 0.01
        for n in names[1:]:
            core.client_data(n, t, f"{n} report {k}".encode())
        core.client_data("surface", t, f"order {k}".encode())
    out = core.run_until_idle()
    assert sum(core.counters(n)["lost_collision"] for n in names) == 0
    assert sum(core.counters(n)["lost_snr"] for n in names) == 0
    reports = [d for d in out if d.node == "surface"]
    assert len(reports) == 15 * frames
    assert {d.source for d in reports} == set(names[1:])
    for n in names[1:]:
        orders = [d.data for d in out if d.node == n]
        assert orders == [f"order {k}".encode() for k in range(frames)], n
    # Everything was sent inside its node's slot.
    slot = scen.tdma.frame / 16
    for d in out:
        into = (d.sent_at + 1e-6) % scen.tdma.frame
        assert scen.slot_of(d.source) * slot <= into < (scen.slot_of(d.source) + 1) * slot


def test_unicast_between_vehicles_is_overheard_by_the_others_but_delivered_to_one():
    scen = replace(load_scenario(FLEET), snr=None)
    scen = replace(scen, nodes=[replace(n, dest="auv2") if n.name == "auv1" else n
                                for n in scen.nodes])
    core = EmulatorCore(scen)
    for n in scen.names():
        core.client_attached(n, 0.0)
    core.client_data("auv1", 0.0, b"hi auv2")
    out = core.run_until_idle()
    assert [(d.node, d.data) for d in out] == [("auv2", b"hi auv2")]


@pytest.mark.parametrize("count", [16, 32])
def test_csma_aloha_with_many_nodes_delivers_some_and_counts_every_loss(count):
    # Without TDMA, a saturated fleet collides; every packet sent to the surface is either
    # delivered or counted lost there.
    nodes = [NodeSpec("surface", dest=BROADCAST)] + [
        NodeSpec(f"v{i}", position=(100.0 + 20 * i, 0.0, 0.0), dest="surface")
        for i in range(count - 1)]
    core = EmulatorCore(Scenario(nodes=nodes, period=0.2, bitrate=4800.0, seed=3))
    for n in nodes:
        core.client_attached(n.name, 0.0)
        core.client_data(n.name, 0.0, bytes(64 * 20))
    core.run_until_idle()
    surface = core.counters("surface")
    sent_to_surface = sum(core.counters(n.name)["packets_sent"] for n in nodes[1:])
    lost = sum(surface[f"lost_{c}"] for c in ("per", "snr", "collision", "no_client"))
    assert surface["packets_delivered"] + lost == sent_to_surface == 20 * (count - 1)
    assert 0 < surface["packets_delivered"] < sent_to_surface
