"""Drive emulated nodes from ROS poses: each node with a `pose_topic` follows that topic.

    feeds = PoseFeeds(emu, scenario)      # an rclpy node subscribed to every pose_topic
    feeds.start(); ...; feeds.stop()

Each message's position (uwgen.emulator.motion.position_from_msg) is scaled and offset as
the scenario says and handed to `Emulator.set_position`. A message without a position
is counted and logged (throttled), never fatal.
"""
from __future__ import annotations

import importlib
import logging
import threading

from uwgen.emulator.motion import position_from_msg
from uwgen.runtime.stats import log_count

log = logging.getLogger("uwgen.emulator")


class PoseFeedError(RuntimeError):
    """A pose topic's type cannot be loaded (not installed / not built)."""


def load_type(type_name: str):
    """The rclpy class of `pkg/msg/Name`; PoseFeedError if it cannot be imported here."""
    package, _, name = type_name.split("/")
    try:
        cls = getattr(importlib.import_module(f"{package}.msg"), name)
        if not hasattr(cls, "_TYPE_SUPPORT"):
            raise AttributeError("it is not a ROS message class")
        return cls
    except (AttributeError, ImportError) as exc:
        raise PoseFeedError(f"pose type {type_name} is not available to rclpy here: {exc}") from None


class PoseFeeds:
    """One rclpy node subscribed to the scenario's pose topics, spun in a thread."""

    def __init__(self, emu, scenario, node_name: str = "uwgen_emulator_poses"):
        self.emu = emu
        self.feeds = {spec.name: spec.pose_topic for spec in scenario.nodes
                      if spec.pose_topic is not None}
        self.received = dict.fromkeys(self.feeds, 0)
        self.bad = dict.fromkeys(self.feeds, 0)
        self._types = {name: load_type(feed.type) for name, feed in self.feeds.items()}
        self._node_name = node_name
        self._context = None
        self._node = None
        self._executor = None
        self._thread: threading.Thread | None = None

    def start(self) -> "PoseFeeds":
        try:
            import rclpy
            from rclpy.executors import SingleThreadedExecutor
        except ImportError as exc:
            raise PoseFeedError(f"pose topics need ROS 2 (rclpy) in this environment: {exc}") from None

        self._context = rclpy.Context()
        rclpy.init(context=self._context)
        self._node = rclpy.create_node(self._node_name, context=self._context)
        for name, feed in self.feeds.items():
            self._node.create_subscription(self._types[name], feed.topic,
                                           self._callback(name, feed), 10)
            log.info("node %s: position follows %s (%s) x %g + %s", name, feed.topic,
                     feed.type, feed.scale, list(feed.offset))
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, name="uwgen-poses", daemon=True)
        self._thread.start()
        return self

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except Exception:  # noqa: BLE001 - the context was shut down under it
            pass

    def _callback(self, name: str, feed):
        def on_pose(msg) -> None:
            try:
                pos = feed.to_position(position_from_msg(msg))
            except ValueError as exc:
                self.bad[name] += 1
                log_count(log, logging.WARNING, self.bad[name],
                          "node %s: pose message ignored: %s", name, exc)
                return
            self.emu.set_position(name, pos)
            self.received[name] += 1
        return on_pose

    def stop(self) -> None:
        if self._executor is not None:
            self._executor.shutdown()
        if self._node is not None:
            self._node.destroy_node()
        if self._context is not None:
            self._context.try_shutdown()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self) -> "PoseFeeds":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
