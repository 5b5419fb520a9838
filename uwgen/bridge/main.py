"""Start one side's bridge: shared by `uwgen bridge` and the generated `bridge_<side>` modules.

Precedence of settings: `--ros-args -p name:=value` parameters, then these flags, then
the manifest's side entry (host, port, max_read_length, period).

Exit status: 0 after a clean stop (SIGINT/SIGTERM), 2 for bad input (unknown side,
bad option, missing generated package).
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import traceback
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Sequence

from uwgen.argtypes import number, whole
from uwgen.bridge.plan import TIMEOUT_REPLIES, BridgePlan, PlanError, import_package
from uwgen.bridge.security import check_security

EXIT_USAGE = 2
log = logging.getLogger("uwgen.bridge")


def add_link_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags common to `uwgen bridge` and the generated modules."""
    parser.add_argument("--host", help="DESERT node host (default: the manifest's side entry)")
    parser.add_argument("--port", type=int, help="DESERT node TCP port (default: the manifest's)")
    parser.add_argument("--max-read-length", type=whole(1, 4096), metavar="BYTES",
                        help="bytes per acoustic packet (DESERT's max_read_length, at least "
                             "what the network's packets need: 47 with security on; default: "
                             "the manifest's side entry)")
    parser.add_argument("--period", type=number(0.001, 3600), metavar="SECONDS",
                        help="seconds between packets (DESERT's period_; default: the "
                             "manifest's side entry)")
    parser.add_argument("--status-period", type=number(0, 3600), default=2.0, metavar="SECONDS",
                        help="seconds between ~/status messages (default 2; 0: none)")
    parser.add_argument("--timeout-reply", choices=TIMEOUT_REPLIES, default="none",
                        help="what a stand-in service answers when its bridged call times out: "
                             "none (no response; the caller's timeout detects it; default) or "
                             "default (a default-constructed response)")
    parser.add_argument("--stats-file", type=Path, metavar="PATH",
                        help="also write the status JSON to this file (periodically and at exit)")
    parser.add_argument("--key-file", type=Path, metavar="PATH",
                        help="network key of the secure link (default: the manifest's security "
                             "key_file)")
    parser.add_argument("--diagnostics-period", type=number(0, 3600), default=1.0, metavar="SECONDS",
                        help="seconds between /diagnostics messages (default 1; 0: none)")
    record = parser.add_argument_group("recording (docs/operators.md)")
    record.add_argument("--record", type=Path, metavar="PATH.mcap",
                        help="record every packet, the messages taken and published and the "
                             "status to this MCAP file (Foxglove, `uwgen log`)")
    record.add_argument("--record-max-mb", type=number(0.01, 1e6), default=64.0, metavar="MB",
                        help="start a new file (PATH.1.mcap, ...) when one passes this size (default 64)")
    record.add_argument("--record-keep", type=whole(0, 100000), default=8, metavar="N",
                        help="keep only the newest N recording files (default 8; 0: all)")
    parser.add_argument("--mac", metavar="YAML",
                        help="how the sides share the channel, overriding the manifest's mac: "
                             "section, in its syntax: e.g. '{mode: tdma, frame: 1.0, guard: "
                             "0.35, max_packet_per_slot: 4}' (every side must be given the same)")
    parser.add_argument("--security-state", type=Path, metavar="PATH",
                        help="lock file held while this side runs, so a second copy is refused "
                             "(default: <key file>.<network>.<side>.lock; no state is kept in it)")


def options_from_args(plan: BridgePlan, args: argparse.Namespace):
    return plan.options(host=args.host, port=args.port, max_read_length=args.max_read_length,
                        period=args.period, status_period=args.status_period,
                        timeout_reply=args.timeout_reply, stats_file=args.stats_file,
                        key_file=getattr(args, "key_file", None),
                        security_state=getattr(args, "security_state", None),
                        record=getattr(args, "record", None),
                        record_max_bytes=int(getattr(args, "record_max_mb", 64.0) * 1024 * 1024),
                        record_keep=getattr(args, "record_keep", None),
                        diagnostics_period=getattr(args, "diagnostics_period", None))


def run(package: ModuleType, side: str, args: argparse.Namespace,
        ros_args: Sequence[str] | None = None, link_factory: Any = None,
        stop: threading.Event | None = None) -> int:
    """Run the bridge until SIGINT/SIGTERM (or `stop`, set by the caller's own handlers).
    `ros_args` go to rclpy.init (e.g. --ros-args ...)."""
    # A package of another uwgen first: nothing else it says can be trusted (its key set-up included).
    from uwgen.codegen.vendor import foreign_runtime
    problem = foreign_runtime(package)
    if problem:
        print(f"uwgen bridge: {problem}", file=sys.stderr)
        return EXIT_USAGE
    try:
        plan = BridgePlan.from_package(package, side, getattr(args, "manifest", None))
        if getattr(args, "mac", None):
            plan = with_mac(plan, args.mac)
        options = options_from_args(plan, args)
        check_security(plan, options)
    except PlanError as exc:
        print(f"uwgen bridge: {exc}", file=sys.stderr)
        return EXIT_USAGE

    # SIGINT/SIGTERM from here on (while rclpy still imports, too) only ask the bridge to stop.
    stop, previous = catch_stop_signals() if stop is None else (stop, {})
    try:
        return _run(package, side, plan, options, ros_args, link_factory, stop)
    finally:
        restore_signals(previous)


def with_mac(plan: BridgePlan, text: str) -> BridgePlan:
    """`plan` under the MAC given by --mac (PlanError when it does not read)."""
    from dataclasses import replace

    from uwgen.manifest.mac import mac_from_text
    from uwgen.manifest.nodes import ManifestError
    try:
        return replace(plan, mac=mac_from_text(text, list(plan.side_ids)))
    except ManifestError as exc:
        raise PlanError(f"--mac: {exc.message if exc.where is None else exc}") from None


def catch_stop_signals() -> tuple[threading.Event, dict]:
    """Make SIGINT and SIGTERM set an event instead of raising KeyboardInterrupt wherever the
    program happens to be (importing rclpy takes a second): the bridge then stops cleanly,
    with its final status, or before it started. Returns the event and the old handlers."""
    stop = threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    return stop, previous


def restore_signals(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


def _run(package: ModuleType, side: str, plan: BridgePlan, options, ros_args, link_factory,
         stop: threading.Event) -> int:
    from uwgen.typesupport import BuildError, activate_recorded
    no_support = ""
    try:  # the type support of the package's own interfaces (uwgen ros-interfaces builds it)
        for env in activate_recorded(getattr(package, "ROS_INTERFACES", {}), fix=_rebuild(package)):
            log.info("using the rclpy type support of %s built in %s", env.package, env.prefix)
    except BuildError as exc:
        no_support = str(exc)
        log.error("%s; their topics and services are not bridged", exc)

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from uwgen.bridge.node import BridgeNode, default_link_factory

    if stop.is_set():
        log.info("stopped before the bridge started")
        return 0
    # Our own SIGINT/SIGTERM handling: stop spinning, then close the node (final status, link
    # stopped) while the ROS context is still valid, then shut ROS down.
    rclpy.init(args=["uwgen-bridge", *(ros_args or [])],
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = BridgeNode(plan, options, link_factory=link_factory or default_link_factory)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            spin(executor, stop, rclpy.ok, lambda exc: callback_failed(node, exc))
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            executor.remove_node(node)
            executor.shutdown(timeout_sec=0.5)
    except PlanError as exc:  # bad ROS parameter values, nothing that can be bridged
        print(f"uwgen bridge: {exc}" + (f"; {no_support}" if no_support else ""), file=sys.stderr)
        return EXIT_USAGE
    finally:
        if node is not None:
            status = node.close()
            if status:
                node_log = logging.getLogger(f"uwgen.bridge.{side}")
                node_log.info("final status: %s", _summary(status))
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def spin(executor: Any, stop: threading.Event, ok: Callable[[], bool],
         failed: Callable[[BaseException], None]) -> None:
    """Spin until `stop` is set or ROS shuts down (`ok` false). A callback that raises is a
    bug (every expected failure is counted where it happens): it is told to `failed`
    (`callback_failed`) and spinning goes on, so the vehicle is not left unbridged."""
    from rclpy.executors import ExternalShutdownException
    while not stop.is_set() and ok():
        try:
            executor.spin_once(timeout_sec=0.2)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except Exception as exc:
            if not ok():
                break                # ROS shut down during the spin: not a callback's bug
            failed(exc)


def callback_failed(node: Any, exc: BaseException) -> None:
    """A callback of the bridge `node` raised: the first of each kind is logged with its
    traceback, all are counted (`callback_errors` in ~/status) and summarised."""
    node.counters.callback_errors += 1
    key = f"callback:{type(exc).__name__}"
    if key not in node.wiring.throttle.totals:
        node.wiring.log.error("a callback failed; the bridge goes on (please report this): "
                              + "".join(traceback.format_exception(exc)).rstrip())
    node.wiring.throttle.report(key, f"a callback failed: {type(exc).__name__}: {exc}")


def _rebuild(package: ModuleType) -> str | None:
    """The command that rebuilds `package` with its interfaces' type support, run in its
    project (None: the package does not say where it was built)."""
    from uwgen.buildinfo import own_manifest, rebuild_hint
    manifest = own_manifest(package)
    if manifest is None:
        return None
    return rebuild_hint(package.BUILT_FROM, manifest, Path(package.__file__).parent)


def _summary(status: dict) -> str:
    parts = []
    for name, t in status.get("topics", {}).items():
        acc = t.get("accounting") or {}
        if t["direction"] == "out":
            dropped = sum(acc.get("dropped_by_policy", {}).values())
            parts.append(f"{name} published {acc.get('published', '?')} taken {t['taken']} sent "
                         f"{acc.get('sent', '?')} dropped {dropped} queued {acc.get('queued', '?')}")
        else:
            parts.append(f"{name} received {t['received']} lost on link {acc.get('lost_on_link', 0)} "
                         f"delivered {t['published']}")
    for name, s in status.get("services", {}).items():
        if s["role"] == "client":
            parts.append(f"{name} calls {s['local_calls']} ok {s['responses']} timeouts {s['timeouts']}")
        else:
            parts.append(f"{name} requests {s['requests']} replies {s['replies']}")
    for name, a in status.get("actions", {}).items():
        if a["role"] == "client":
            parts.append(f"{name} goals {a['goals']} accepted {a['accepted']} results {a['results']}")
        else:
            parts.append(f"{name} goals {a['goal_requests']} results {a['results_sent']}")
    security = status.get("security")
    if security:
        parts.append(f"security: protected {security['protected']} verified {security['verified']} "
                     f"dropped {security['dropped']}")
    discovery = status.get("discovery")
    if discovery:
        remote = discovery.get("remote", [])
        nodes = sorted({e["node"] for e in remote})
        parts.append(f"rmw_desert remote graph: {len(remote)} entities"
                     + (f" of {', '.join(nodes)}" if nodes else ""))
    return "; ".join(parts)


def main(package: str | ModuleType, side: str | None = None,
         argv: Sequence[str] | None = None) -> int:
    """Entry point of a generated `bridge_<side>` module."""
    stop, previous = catch_stop_signals()    # before anything imports rclpy
    try:
        return _main(package, side, argv, stop)
    finally:
        restore_signals(previous)


def _main(package: str | ModuleType, side: str | None, argv: Sequence[str] | None,
          stop: threading.Event) -> int:
    from rclpy.utilities import remove_ros_args

    argv = list(sys.argv[1:] if argv is None else argv)
    user_args = remove_ros_args(["prog", *argv])[1:]
    name = package if isinstance(package, str) else package.__name__
    parser = argparse.ArgumentParser(
        prog=f"python -m {name}.bridge_{side}" if side else f"python -m {name}",
        description=f"uwgen bridge node of {name}" + (f", side {side}" if side else ""))
    if side is None:
        parser.add_argument("--side", required=True)
    add_link_arguments(parser)
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(user_args)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    try:
        module = import_package(name) if isinstance(package, str) else package
    except PlanError as exc:
        print(f"uwgen bridge: {exc}", file=sys.stderr)
        return EXIT_USAGE
    # In its project's generated/, the package checks itself against its manifest there.
    from uwgen.buildinfo import own_manifest, stale_message
    manifest = own_manifest(module)
    problem = stale_message(module, manifest) if manifest is not None else None
    if problem:
        print(f"uwgen bridge: {problem}", file=sys.stderr)
        return EXIT_USAGE
    # rclpy.init reads only the --ros-args sections of argv and leaves the rest alone.
    return run(module, side or args.side, args, argv, stop=stop)
