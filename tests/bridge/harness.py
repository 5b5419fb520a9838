"""One ROS "machine" per test side: an rclpy context in its own domain, spun in a thread.

Two sides of a bridge test live in one process but in different ROS domains, as a
vehicle and a surface computer would, so their graphs never see each other.
"""
from __future__ import annotations

import gc
import random
import threading
from contextlib import contextmanager

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.bridge.rosnode import destroy_waitables

from .fakes import next_domain


class RosSide:
    def __init__(self, name: str, domain_id: int | None = None):
        self.name = name
        self.domain_id = next_domain() if domain_id is None else domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain_id,
                   signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list = []
        self._closing = False
        self._thread = threading.Thread(target=self._spin, name=f"spin-{name}", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except (ExternalShutdownException, rclpy.executors.ShutdownException):
            pass
        except RuntimeError:
            # rclpy's RCLError: close() shut the context down while the spin still waited
            # (executor.shutdown's 1 s ran out on a loaded machine); any other is the test's
            if not self._closing:
                raise

    def node(self, name: str):
        node = rclpy.create_node(name, context=self.context)
        self.add(node)
        return node

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def close(self) -> None:
        self._closing = True
        for node in reversed(self.nodes):
            close = getattr(node, "close", None)
            try:
                self.executor.remove_node(node)
                close() if close else destroy_with_waitables(node)
            except Exception:
                pass
        self.executor.shutdown(timeout_sec=1.0)
        if self.context.ok():
            rclpy.shutdown(context=self.context)
        self._thread.join(timeout=2.0)
        # Shutting a context down leaves its DDS participant alive until the context is
        # destroyed, which waits until nothing uses it: action clients and servers hold their
        # node, and Node.destroy_node leaves them (waitables) to garbage collection, maybe
        # never in a test run. A later test in the same domain then saw this side's bridge
        # or action server in its graph (its loop guard stopped bridging, a goal went to the
        # old server). The bridge destroys its own (uwgen.bridge.rosnode); the test's
        # nodes have theirs destroyed here.
        self.nodes.clear()
        self.context.destroy()
        gc.collect()


def destroy_with_waitables(node) -> None:
    """Destroy `node` and the action clients and servers made on it."""
    destroy_waitables(node)
    node.destroy_node()


def start_bridge(side: RosSide, package, link_factory, *, flush_timeout: float | None = None,
                 **options) -> BridgeNode:
    """The bridge of `side.name` in that side's context, without ~/status timer; `options`
    override the manifest's (BridgePlan.options)."""
    plan = BridgePlan.from_package(package, side.name)
    node = BridgeNode(plan, plan.options(status_period=0, **options), link_factory=link_factory,
                      context=side.context, rng=random.Random(3), flush_timeout=flush_timeout)
    return side.add(node)


@contextmanager
def ros_sides(*names: str, same_domain: bool = False):
    sides = []
    try:
        shared = next_domain() if same_domain else None
        for n in names:
            sides.append(RosSide(n, shared))
        yield sides
    finally:
        for s in reversed(sides):
            s.close()
