"""RemoteGraph keeps what remote nodes announced, and forgets what they withdrew."""
from __future__ import annotations

import json

from uwgen.interop.beacons import Beacon, Entity
from uwgen.interop.graph import (
    ADDED, CHANGED, IGNORED_OWN, REFRESHED, REMOVED, UNKNOWN_DISCONNECT, RemoteGraph,
    format_graph)
from uwgen.runtime.clock import ManualClock

GID_A = bytes(range(16))
GID_B = bytes(range(1, 17))


def server(gid=GID_A, topic="/set_bool", node="turtlesim"):
    return Beacon(node, "/", Entity.SERVICE, gid, topic, "std_srvs__srv/SetBool_Response")


def test_beacon_adds_entity_with_node_topic_and_ros_type():
    graph = RemoteGraph(clock=ManualClock(5.0))
    assert graph.observe(server()) == ADDED
    [entity] = graph.entities()
    assert (entity.node, entity.entity, entity.topic, entity.ros_type) == (
        "/turtlesim", Entity.SERVICE, "/set_bool", "std_srvs/srv/SetBool")
    assert graph.has(Entity.SERVICE, "/set_bool")
    assert not graph.has(Entity.CLIENT, "/set_bool")


def test_repeated_beacon_refreshes_last_heard_only():
    clock = ManualClock(1.0)
    graph = RemoteGraph(clock=clock)
    graph.observe(server())
    clock.advance(3.0)
    assert graph.observe(server()) == REFRESHED
    [entity] = graph.entities()
    assert (entity.first_heard, entity.last_heard) == (1.0, 4.0)
    assert len(graph) == 1


def test_disconnect_beacon_removes_the_entity_by_gid():
    graph = RemoteGraph(clock=ManualClock())
    graph.observe(server(GID_A))
    graph.observe(server(GID_B, topic="/other"))
    assert graph.observe(server(GID_A).gone()) == REMOVED
    assert [e.topic for e in graph.entities()] == ["/other"]
    assert not graph.has(Entity.SERVICE, "/set_bool")


def test_disconnect_for_unknown_gid_is_counted_not_raised():
    graph = RemoteGraph(clock=ManualClock())
    assert graph.observe(server().gone()) == UNKNOWN_DISCONNECT
    assert graph.counts()[UNKNOWN_DISCONNECT] == 1 and len(graph) == 0


def test_own_gids_are_ignored():
    graph = RemoteGraph(clock=ManualClock(), own_gids=frozenset({GID_A}))
    assert graph.observe(server(GID_A)) == IGNORED_OWN
    assert len(graph) == 0


def test_gid_announcing_something_else_replaces_it():
    graph = RemoteGraph(clock=ManualClock())
    graph.observe(server(GID_A, topic="/a"))
    assert graph.observe(server(GID_A, topic="/b")) == CHANGED
    assert [e.topic for e in graph.entities()] == ["/b"]


def test_snapshot_is_json_and_table_lists_every_entity():
    graph = RemoteGraph(clock=ManualClock())
    graph.observe(server())
    graph.observe(Beacon("teleop", "/ns", Entity.PUBLISHER, GID_B, "/turtle1/cmd_vel",
                         "geometry_msgs__msg/Twist"))
    snap = json.loads(json.dumps(graph.as_dict()))
    assert [e["node"] for e in snap["entities"]] == ["/ns/teleop", "/turtlesim"]
    assert snap["beacons"][ADDED] == 2
    table = format_graph(graph.entities())
    assert "/ns/teleop" in table and "geometry_msgs/msg/Twist" in table
    assert "service" in table.splitlines()[2]
    assert format_graph([]) == "no remote entities heard"
