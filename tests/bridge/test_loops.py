"""The loop guard's reading of the ROS graph (uwgen.bridge.loops), on a fake graph."""
from __future__ import annotations

from uwgen.bridge.loops import LoopGuard


class FakeGraph:
    """What LoopGuard asks of an rclpy node: nodes, and the services/clients of each."""

    def __init__(self, me=("uwgen_bridge_net_surface", "/")):
        self.me = me
        self.services: dict[tuple[str, str], list[str]] = {me: []}
        self.clients: dict[tuple[str, str], list[str]] = {me: []}

    def get_name(self):
        return self.me[0]

    def get_namespace(self):
        return self.me[1]

    def get_node_names_and_namespaces(self):
        return sorted(set(self.services) | set(self.clients))

    def get_service_names_and_types_by_node(self, name, ns):
        return [(s, ["t"]) for s in self.services.get((name, ns), [])]

    def get_client_names_and_types_by_node(self, name, ns):
        return [(s, ["t"]) for s in self.clients.get((name, ns), [])]


class Log:
    def __init__(self):
        self.lines = []

    def error(self, text):
        self.lines.append(("error", text))

    def info(self, text):
        self.lines.append(("info", text))


def test_a_stand_in_is_blocked_by_another_bridges_client_of_it():
    graph, log = FakeGraph(), Log()
    guard = LoopGuard(graph, log)
    guard.watch_standin("/echo")
    assert not guard.blocked("/echo")
    graph.clients[("uwgen_bridge_net_vehicle", "/")] = ["/echo"]
    assert guard.blocked("/echo") and guard.blocked("/echo")
    assert guard.hazards == {"/echo": "uwgen_bridge_net_vehicle"}
    assert len(log.lines) == 1 and "ROS_DOMAIN_ID" in log.lines[0][1]      # said once


def test_a_server_side_is_blocked_by_another_bridge_offering_it():
    graph, log = FakeGraph(), Log()
    guard = LoopGuard(graph, log)
    guard.watch_server("/fib", action=True)
    graph.services[("uwgen_bridge_net_vehicle", "/")] = ["/fib"]            # not the action's
    assert not guard.blocked("/fib")
    graph.services[("uwgen_bridge_net_vehicle", "/")] = ["/fib/_action/send_goal"]
    assert guard.blocked("/fib")


def test_own_node_and_other_nodes_never_block():
    graph, log = FakeGraph(), Log()
    guard = LoopGuard(graph, log)
    guard.watch_standin("/echo")
    guard.watch_server("/pen")
    graph.clients[graph.me] = ["/echo"]
    graph.services[graph.me] = ["/pen"]
    graph.clients[("operator", "/")] = ["/echo"]
    graph.services[("turtlesim", "/")] = ["/pen"]
    assert not guard.blocked("/echo") and not guard.blocked("/pen")
    assert log.lines == []


def test_the_periodic_look_withdraws_and_restores_a_stand_in():
    graph, log = FakeGraph(), Log()
    guard = LoopGuard(graph, log)
    changes = []
    guard.watch_standin("/echo", on_change=changes.append)
    guard.check_graph()
    graph.clients[("uwgen_bridge_net_vehicle", "/")] = ["/echo"]
    guard.check_graph()
    del graph.clients[("uwgen_bridge_net_vehicle", "/")]
    guard.check_graph()
    assert changes == [False, True, False]
    assert [kind for kind, _ in log.lines] == ["error", "info"]


def test_of_two_stand_ins_only_the_bridge_sorting_first_keeps_its_own():
    first, second = ("uwgen_bridge_a_surface", "/"), ("uwgen_bridge_b_surface", "/")
    guards = {}
    for me, other in ((first, second), (second, first)):
        graph = FakeGraph(me)
        graph.services[me] = ["/echo"]
        graph.services[other] = ["/echo"]
        guards[me] = LoopGuard(graph, Log())
        guards[me].watch_standin("/echo")
    assert not guards[first].blocked("/echo")
    assert guards[second].blocked("/echo")
    assert guards[second].hazards == {"/echo": first[0]}


def test_a_withdrawn_second_stand_in_returns_when_the_first_is_gone():
    me, other = ("uwgen_bridge_b_surface", "/"), ("uwgen_bridge_a_surface", "/")
    graph, log = FakeGraph(me), Log()
    graph.services[other] = ["/fib/_action/send_goal"]
    guard = LoopGuard(graph, log)
    guard.watch_standin("/fib", action=True)
    assert guard.blocked("/fib")
    graph.services[other] = []
    assert not guard.blocked("/fib")
    assert [kind for kind, _ in log.lines] == ["error", "info"]
