"""The `fleet:` section: N vehicles expanded at load, each with its own side, namespace, ids,
sender id and peers; every mistake a located error."""
from __future__ import annotations

import pytest

from uwgen.manifest.model import takes_part

from .helpers import error_of, load_text, write_manifest

# Lines: 1 network, 2 sides:, 3 surface, 4 fleet:, 5 vehicles, 6 name, 7 port, 8 sender_id,
# 9 topics:, 10 name, 11 id, 12 type, 13 publisher, 14 - name, 15 id, 16 type, 17 publisher,
# 18 services:, 19 name, 20 id, 21 type, 22 server, 23 actions:, 24 name, 25 id, 26 type, 27 server
FLEET = """
        network: survey
        sides:
          surface: {port: 4000, sender_id: 1}
        fleet:
          vehicles: 3
          name: auv{n}
          port: 4001
          sender_id: 2
          topics:
            - name: pose
              id: 10
              type: std_msgs/msg/String
              publisher: fleet
            - name: cmd
              id: 11
              type: std_msgs/msg/String
              publisher: surface
          services:
            - name: set_pen
              id: 12
              type: turtlesim/srv/SetPen
              server: fleet
          actions:
            - name: go
              id: 13
              type: test_msgs/action/Fibonacci
              server: fleet
"""


def fleet(**changes: str) -> str:
    text = FLEET
    for old, new in changes.items():
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def test_each_vehicle_is_a_side_in_turn_order_with_its_own_port_and_sender_id(tmp_path):
    m = load_text(tmp_path, FLEET)
    assert list(m.sides) == ["surface", "auv1", "auv2", "auv3"]
    assert [m.sides[v].port for v in ("auv1", "auv2", "auv3")] == [4001, 4002, 4003]
    assert m.security.senders == {"surface": 1, "auv1": 2, "auv2": 3, "auv3": 4}
    assert m.fleet.vehicles == ("auv1", "auv2", "auv3")
    assert m.fleet.namespaces == {"auv1": "/auv1", "auv2": "/auv2", "auv3": "/auv3"}
    assert m.fleet.leaders == ("surface",) and m.fleet.id_stride == 4


def test_each_vehicle_gets_its_entries_under_its_namespace_with_ids_a_stride_apart(tmp_path):
    m = load_text(tmp_path, FLEET)
    pose = {t.name: (t.id, t.publisher, t.peers) for t in m.topics if t.name.endswith("/pose")}
    assert pose == {"/auv1/pose": (10, "auv1", ("surface", "auv1")),
                    "/auv2/pose": (14, "auv2", ("surface", "auv2")),
                    "/auv3/pose": (18, "auv3", ("surface", "auv3"))}
    cmd = {t.name: (t.id, t.publisher) for t in m.topics if t.name.endswith("/cmd")}
    assert cmd == {"/auv1/cmd": (11, "surface"), "/auv2/cmd": (15, "surface"), "/auv3/cmd": (19, "surface")}
    assert [(s.name, s.id, s.server) for s in m.services] == [
        ("/auv1/set_pen", 12, "auv1"), ("/auv2/set_pen", 16, "auv2"), ("/auv3/set_pen", 20, "auv3")]
    assert [(a.name, a.id, a.server) for a in m.actions] == [
        ("/auv1/go", 13, "auv1"), ("/auv2/go", 17, "auv2"), ("/auv3/go", 21, "auv3")]
    # Errors in a copy point at the template's line.
    assert m.entry(18).where.line == m.entry(10).where.line == 10


def test_a_command_is_addressed_to_one_vehicle_and_the_surface_takes_part_in_all(tmp_path):
    m = load_text(tmp_path, FLEET)
    cmd2 = m.entry(15)
    assert cmd2.name == "/auv2/cmd"
    assert [side for side in m.sides if takes_part(cmd2, side)] == ["surface", "auv2"]
    assert all(takes_part(e, "surface") for e in (*m.topics, *m.services, *m.actions))
    assert m.fleet.vehicle_of(cmd2) == "auv2"


def test_an_action_of_one_vehicle_shares_its_goal_handles_with_the_surface_only(tmp_path):
    # Only the surface calls /auv1/go: it keeps the default 4 goals in flight, where 3
    # client sides would have left 8 handles each.
    m = load_text(tmp_path, FLEET)
    assert {a.max_goals for a in m.actions} == {4}


def test_top_level_entries_stay_shared_by_every_side(tmp_path):
    m = load_text(tmp_path, FLEET + """
        topics:
          - {name: /fleet/order, id: 40, type: std_msgs/msg/String, publisher: surface}
    """)
    order = m.entry(40)
    assert order.peers == () and all(takes_part(order, s) for s in m.sides)


def test_vehicles_may_be_named_by_a_list_and_the_namespace_pattern_uses_n_and_name(tmp_path):
    m = load_text(tmp_path, fleet(**{"vehicles: 3\n          name: auv{n}":
                                     "vehicles: [alpha, bravo]\n          namespace: /fleet/{name}_{n}"}))
    assert list(m.sides) == ["surface", "alpha", "bravo"]
    assert m.fleet.namespaces == {"alpha": "/fleet/alpha_1", "bravo": "/fleet/bravo_2"}
    assert m.entry(14).name == "/fleet/bravo_2/pose"


def test_the_mac_gives_every_vehicle_a_slot_in_turn_order(tmp_path):
    from uwgen.manifest.mac import mac_of_file
    text = FLEET.replace("        fleet:", "        mac: {mode: tdma, frame: 2.0, guard: 0.1}\n        fleet:")
    m = load_text(tmp_path, text)
    assert m.mac.slots == ("surface", "auv1", "auv2", "auv3")
    assert mac_of_file(write_manifest(tmp_path, text)).slots == m.mac.slots     # as the demo reads it


@pytest.mark.parametrize("change, line, column, words", [
    ({"vehicles: 3": "vehicles: 15", "surface: {port: 4000, sender_id: 1}":
      "surface: {port: 4000, sender_id: 1}\n          shore: {port: 3999, sender_id: 0}"},
     6, 13, "is 17 sides"),
    ({"vehicles: 3": "vehicles: 16"}, 5, 13, "must be in 1..15"),
    ({"sender_id: 2": "sender_id: 14"}, 8, 14, "sender id 16"),
    ({"port: 4001": "port: 65534"}, 7, 9, "past 65535"),
    ({"port: 4001": "port: 4000"}, 7, 9, "already used by side 'surface'"),
    ({"name: auv{n}": "name: auv"}, 6, 9, "must contain {n}"),
    ({"name: pose": "name: /pose"}, 10, 13, "must be relative"),
    ({"publisher: fleet": "publisher: auv2"}, 13, 18, "must be 'fleet'"),
    ({"sender_id: 2\n": "sender_id: 2\n          id_stride: 125\n"}, 12, 11, "is 260 for vehicle 3"),
    ({"sender_id: 2\n": "sender_id: 2\n          id_stride: 3\n"}, 9, 14, "smaller than the span"),
])
def test_fleet_mistakes_are_located_errors(tmp_path, change, line, column, words):
    err = error_of(tmp_path, fleet(**change))
    assert words in err.message
    assert (err.where.line, err.where.column) == (line, column), err.message


def test_an_expanded_id_that_a_top_level_entry_uses_is_a_located_duplicate(tmp_path):
    err = error_of(tmp_path, FLEET + """
        topics:
          - {name: /fleet/order, id: 16, type: std_msgs/msg/String, publisher: surface}
    """)
    assert "id 16" in err.message and "already used by" in err.message


def test_a_sender_id_an_expanded_vehicle_shares_with_the_surface_is_refused(tmp_path):
    err = error_of(tmp_path, fleet(**{"sender_id: 2": "sender_id: 0"}))
    assert "sender_id 1 of side 'auv2'" in err.message and "surface" in err.message
    assert err.where.line == 8


def test_a_template_error_is_reported_once_not_per_vehicle(tmp_path):
    err = error_of(tmp_path, fleet(**{"type: std_msgs/msg/String": "type: std_msgs/msg/Nope"}))
    assert len(getattr(err, "errors", [err])) == 1 and err.where.line == 12
