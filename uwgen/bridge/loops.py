"""Loop guard for services and actions: another uwgen bridge in the same ROS graph.

Two bridges of one network that share a ROS graph (a user who forgot ROS_DOMAIN_ID) would
pass calls around in a circle: the serving bridge's client of the real service also
reaches the calling bridge's stand-in, which sends the call over the link to the serving
bridge, which calls again... (one call ran the real server 15 times, one goal ran until the
processes were killed). rclpy in Jazzy tells neither a service callback who called nor
which node a request came from, so the guard works from the graph, as the topic guard
(`topics.TopicBridge.check_graph`) does:

- a **stand-in** (this side offers a service or action served elsewhere) is not bridged
  while another uwgen bridge node in this graph has a *client* of that name: that bridge
  serves it from here, so what the stand-in forwarded could come back. The stand-in is
  withdrawn from the graph (its service or action server destroyed, made again when the
  hazard is gone), so local clients reach only the real server in this graph; calls and
  goals it gets before it is withdrawn are never answered by it; counted `loop_guard`;
- two **stand-ins** of one name in one graph (two bridges that both offer it, e.g. two
  operator stations of one vehicle, or two networks' surfaces) would each forward one local
  call, and the far side would run it twice (a ROS request reaches every server of its name):
  only the bridge whose node name sorts first keeps its stand-in; the others withdraw theirs
  while it is there (a deterministic choice both sides make alike, so exactly one stays);
- a **server side** (this side calls the real service or action server) does not call it
  for a request from the link while another uwgen bridge node in this graph *offers* that
  name: its call would reach that bridge's stand-in and go round. Counted `loop_guard`.

Each side checks the graph when a call or goal comes (so the first one is already
guarded) and every GRAPH_TICK, to say once, clearly, when the hazard appears and when it
is gone. Either check alone breaks the circle; both together also cover the time one
bridge has discovered the other and the other not yet.
"""
from __future__ import annotations

from typing import Any, Callable

OnChange = Callable[[bool], None]   # called with True when a hazard appears, False when gone

BRIDGE_NODE_PREFIX = "uwgen_bridge_"
SEND_GOAL = "/_action/send_goal"   # the service an action server offers, an action client calls


def graph_name(name: str, action: bool) -> str:
    """The service name that shows a service or action (`name`) in the ROS graph."""
    return name + SEND_GOAL if action else name


class LoopGuard:
    def __init__(self, node: Any, log: Any):
        self.node, self.log = node, log
        # entry name -> (graph service name, look for clients (True) or servers (False))
        self.watched: dict[str, tuple[str, bool]] = {}
        self.hazards: dict[str, str] = {}          # entry name -> the foreign bridge node
        self.on_change: dict[str, OnChange] = {}

    def watch_standin(self, name: str, action: bool = False,
                      on_change: OnChange | None = None) -> None:
        """This side offers `name`: a foreign bridge's client of it would close a loop.
        `on_change(blocked)` is called from check_graph() (the periodic look) when the
        hazard appears or goes: the stand-in withdraws and comes back."""
        self.watched[name] = (graph_name(name, action), True)
        if on_change is not None:
            self.on_change[name] = on_change

    def watch_server(self, name: str, action: bool = False) -> None:
        """This side calls the real `name`: a foreign bridge offering it would close a loop."""
        self.watched[name] = (graph_name(name, action), False)

    def blocked(self, name: str) -> bool:
        """Look at the graph now: True while `name` must not be bridged (said once)."""
        self._update(name, self._foreign(*self.watched[name]))
        return name in self.hazards

    def check_graph(self) -> None:
        """Every GRAPH_TICK: say when a hazard appears or is gone."""
        for name, (service, clients) in self.watched.items():
            self._update(name, self._foreign(service, clients))
            change = self.on_change.get(name)
            if change is not None:
                change(name in self.hazards)

    def _update(self, name: str, foreign: str | None) -> None:
        service, clients = self.watched[name]
        if foreign is not None and name not in self.hazards:
            self.hazards[name] = foreign
            what = ("has a client of it (it serves it from here) or offers the same stand-in"
                    if clients else "offers it (a stand-in for a server elsewhere)")
            self.log.error(f"{name}: bridge node {foreign} in the same ROS graph {what}, so a call "
                           f"could go round between the two bridges; not bridging {name} until it "
                           "is gone (give each side its own ROS_DOMAIN_ID)")
        elif foreign is None and name in self.hazards:
            del self.hazards[name]
            self.log.info(f"{name}: no other bridge in this ROS graph handles it any more; "
                          "bridging it again")

    def _foreign(self, service: str, clients: bool) -> str | None:
        """The first other bridge node that makes `name` a hazard, or None. For a stand-in
        (`clients`): one with a client of it, or one offering the same stand-in whose
        (name, namespace) sorts before this node's."""
        node = self.node
        me = (node.get_name(), node.get_namespace())
        try:
            nodes = node.get_node_names_and_namespaces()
            lookups = ([(node.get_client_names_and_types_by_node, False),
                        (node.get_service_names_and_types_by_node, True)] if clients
                       else [(node.get_service_names_and_types_by_node, False)])
            for name, namespace in sorted(nodes):
                if not name.startswith(BRIDGE_NODE_PREFIX) or (name, namespace) == me:
                    continue
                for lookup, only_before_me in lookups:
                    if only_before_me and (name, namespace) > me:
                        continue
                    try:
                        if any(s == service for s, _ in lookup(name, namespace)):
                            return name
                    except Exception:   # the node left between the two calls
                        continue
        except Exception:           # the context is shutting down
            return None
        return None
