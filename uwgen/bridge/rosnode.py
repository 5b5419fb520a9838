"""The bridge's rclpy node: destroying it releases every entity made on it.

Node.destroy_node destroys publishers, subscriptions, clients, services, timers and guard
conditions, but leaves waitables (action clients and servers) to garbage collection; while
one lives the node stays in the ROS graph, and its context's DDS participant with it. A
bridge closed (or, in tests, killed) would then be seen by a bridge started later in that
domain: a stand-in "offered elsewhere" (its loop guard stops bridging), a server its goals
may reach.
"""
from __future__ import annotations

from typing import Any

from rclpy.node import Node


def destroy_waitables(node: Any) -> None:
    """Destroy the action clients and servers (any waitable with `destroy`) made on `node`."""
    for waitable in list(node.waitables):
        destroy = getattr(waitable, "destroy", None)
        if destroy is not None:
            destroy()


class WholeNode(Node):
    """An rclpy Node whose destroy_node destroys its waitables first."""

    def destroy_node(self) -> None:
        destroy_waitables(self)
        super().destroy_node()
