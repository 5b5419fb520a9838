"""A fleet's bridge plans: each vehicle bridges its own entries only, the surface all of them;
the others' entries stay known (seal, schema) and what arrives for them is counted overheard."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from uwgen.bridge.counters import BridgeCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.plan import BridgePlan
from uwgen.runtime.wire.codec import pack_items

GENERATED = Path(__file__).resolve().parents[2] / "generated"


@pytest.fixture(scope="module")
def package():
    sys.path.insert(0, str(GENERATED))
    try:
        import uwgen_fleet_demo
        yield uwgen_fleet_demo
    finally:
        sys.path.remove(str(GENERATED))


def names(entries):
    return sorted(e.name for e in entries)


def test_a_vehicle_bridges_its_own_entries_and_hears_the_others(package):
    plan = BridgePlan.from_package(package, "auv2")
    assert names(plan.incoming_topics) == ["/auv2/turtle1/cmd_vel"]
    assert names(plan.outgoing_topics) == ["/auv2/turtle1/pose"]
    assert names(plan.served_services) == ["/auv2/turtle1/teleport_absolute", "/auv2/vehicle/set_pen"]
    assert plan.called_services == [] and plan.offered_actions == []
    assert names(plan.served_actions) == ["/auv2/turtle1/rotate_absolute"]
    assert {e.id for e in plan.overheard} == {10, 11, 12, 13, 14, 30, 31, 32, 33, 34}
    assert all(not name.startswith(("/auv1", "/auv3")) for name in plan.entry_names())


def test_the_surface_bridges_every_vehicle_and_keeps_all_goal_handles(package):
    plan = BridgePlan.from_package(package, "surface")
    assert names(plan.outgoing_topics) == [f"/auv{n}/turtle1/cmd_vel" for n in (1, 2, 3)]
    assert len(plan.called_services) == 6 and len(plan.offered_actions) == 3
    assert plan.overheard == []
    # The surface is the only client of each vehicle's action: all 24 handles are its own.
    assert set(plan.action_handles.values()) == {(0, 23)}


def test_each_side_sends_on_distinct_sender_ids(package):
    ids = {side: BridgePlan.from_package(package, side).sender_id
           for side in ("surface", "auv1", "auv2", "auv3")}
    assert ids == {"surface": 1, "auv1": 2, "auv2": 3, "auv3": 4}


def test_what_arrives_for_another_vehicle_is_counted_overheard_not_unknown():
    counters = BridgeCounters()
    d = Dispatcher(counters)
    d.route(0, 20, lambda ident, payload: None)
    d.overhears(10)
    d.dispatch(pack_items([0, 10, 1.0]))
    d.dispatch(pack_items([0, 99, 1.0]))
    assert (counters.overheard, counters.unknown_id) == (1, 1)
