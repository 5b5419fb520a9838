"""How the demo's ROS applications start ROS and stop on SIGINT or SIGTERM.

rclpy's own signal handler shuts the ROS context down from inside the signal: an executor
waiting at that moment raises RCLError "context is not valid" instead of returning, and
the application exits 1 after a good run (1 demo run in 6 ended so). Here a signal only
sets a flag (or raises KeyboardInterrupt where the application's own loops spin), the
application stops spinning, and then shuts ROS down itself, as the bridge does.
"""
from __future__ import annotations

import signal
import threading


def init_ros(args: list[str]) -> threading.Event:
    """rclpy.init without rclpy's signal handlers; the returned event is set by SIGINT or
    SIGTERM."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    return stop


def spin_until_stopped(node, stop: threading.Event, period: float = 0.1) -> None:
    """Spin `node` until `stop` is set (a signal arrived)."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=period)
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.5)


def interrupt_on_signals(stop: threading.Event) -> None:
    """For an application whose own loops spin: SIGINT and SIGTERM set `stop` and raise
    KeyboardInterrupt in the main thread (the ROS context stays valid until it shuts down)."""
    def handler(*_):
        stop.set()
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)
