"""`uwgen emulate`: run emulated DESERT nodes on 127.0.0.1, or print the PDR sweep.

    uwgen emulate msg_samples/scenarios/two-nodes.yaml
    uwgen emulate -m msg_samples/uwgen.yaml [scenario.yaml]     # sides, ports, links from the manifest
    uwgen emulate --nodes 2 --ports 4000 4001 --distance 1500 --period 0.2 --wind 5
    uwgen emulate --pdr-sweep --wind 0 5 10 --plot docs/pdr-sweep.png

Runs until Ctrl-C or SIGTERM (or --duration), then prints every node's counters.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from pathlib import Path

from uwgen.argtypes import number, whole
from uwgen.commands.options import add_manifest
from uwgen.emulator.physics import DEFAULT_PHY, PHYS

PHY_NAMES = tuple(PHYS)

HELP = "run emulated DESERT nodes (TCP sockets + acoustic channel), or print a PDR sweep"

EXIT_USAGE = 2
EXIT_FAILED = 1

log = logging.getLogger("uwgen.emulator")

COUNTER_COLUMNS = ("bytes_in", "packets_queued", "packets_sent", "packets_delivered",
                   "lost_per", "lost_snr", "lost_collision", "lost_no_client",
                   "queue_bytes", "max_queue_bytes", "dropped_restart", "clients",
                   "max_mac_queue", "dropped_queue_full")


# More nodes than any acoustic network has: the emulator runs one socket server per node.
MAX_NODES = 256


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="?", type=Path,
                        help="YAML scenario (msg_samples/scenarios/*.yaml); flags override it")
    add_manifest(parser, help="one node per side, named after it, with its port and link "
                              "settings; a scenario file then only adds physics (positions, "
                              "waypoints, snr, tdma, seed, ...). Validated as `uwgen build -m` "
                              "validates it (types from the interface packages beside it, or "
                              "installed)")
    g = parser.add_argument_group("nodes (without a scenario file)")
    g.add_argument("--nodes", type=whole(1, MAX_NODES), default=None, metavar="N",
                   help="number of nodes, on a line, each sending to the next (default 2)")
    g.add_argument("--ports", nargs="+", default=None, metavar="PORT",
                   help="one TCP port per node (default 4000, 4001, ...; 0 = any free port); "
                        "a scenario file may follow them")
    g.add_argument("--distance", type=number(0, 1e6), default=None, metavar="M",
                   help="metres between neighbouring nodes (default 1000)")
    link = parser.add_argument_group("link and channel")
    link.add_argument("--period", type=number(0.001, 3600), default=None, metavar="S",
                      help="seconds between packets of a node (DESERT period_, default 0.2)")
    link.add_argument("--max-read-length", type=int, default=None, metavar="BYTES",
                      help="bytes per packet (default 64, at most 4096)")
    link.add_argument("--bitrate", type=number(1, 1e9), default=None, metavar="BPS",
                      help="acoustic bit rate (default 4800)")
    link.add_argument("--per", type=number(0, 1), default=None,
                      help="fixed packet error rate 0..1 on top of the channel model (default: none)")
    link.add_argument("--seed", type=whole(0, 2 ** 64 - 1), default=None, help="random seed (default 1)")
    link.add_argument("--phy", choices=PHY_NAMES, default=None, metavar="NAME",
                      help=f"the channel's SNR model by name: {', '.join(PHY_NAMES)} (default: "
                           f"{DEFAULT_PHY}, the PHY of DESERT's stock two-node scenario, as the "
                           "calibration traces: delivery ends near 3.8 km; thesis: full delivery "
                           "to ~7 km; none: no SNR losses). A scenario file's `snr:` is kept "
                           "unless --phy is given")
    link.add_argument("--wind", type=number(0, 100), nargs="+", default=None, metavar="M_S",
                      help="wind speed of the SNR model (several values with --pdr-sweep; "
                           "default 0, there 0 5 10)")
    link.add_argument("--tdma", type=number(0.001, 3600), default=None, metavar="FRAME",
                      help="use TDMA with this frame length in seconds (slot = frame / nodes; "
                           "default: no TDMA, every node sends when it has data)")
    link.add_argument("--guard", type=number(0, 3600), default=None, metavar="S",
                      help="TDMA guard time in seconds (default 0.05)")
    run_g = parser.add_argument_group("running")
    run_g.add_argument("--duration", type=number(0, 1e9), default=None, metavar="S",
                       help="stop after S seconds (default: until Ctrl-C / SIGTERM)")
    run_g.add_argument("--crash-every", type=number(0, 1e9, above=True), default=None, metavar="S",
                       help="make DESERT crash at random, on average every S seconds (every "
                            "client disconnected, queues lost), as real DESERT does under load")
    run_g.add_argument("--crash-down", type=number(0, 1e9), default=1.0, metavar="S",
                       help="with --crash-every: seconds DESERT stays down (default 1)")
    sweep = parser.add_argument_group("PDR sweep (simulated, no sockets)")
    sweep.add_argument("--pdr-sweep", action="store_true",
                       help="print the delivery ratio against distance for each --wind")
    sweep.add_argument("--plot", type=Path, default=None, metavar="PNG",
                       help="with --pdr-sweep: also save the plot here")
    sweep.add_argument("--packets", type=whole(1, 100_000), default=400,
                       help="with --pdr-sweep: packets per distance (default 400)")


def run(args: argparse.Namespace) -> int:
    from uwgen.emulator.scenario import ScenarioError

    if args.pdr_sweep:
        return _sweep(args)
    if args.plot is not None:
        print("uwgen emulate: --plot needs --pdr-sweep", file=sys.stderr)
        return EXIT_USAGE
    try:
        scenario = build_scenario(args)
    except ScenarioError as exc:
        print(f"uwgen emulate: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.crash_every is not None and not (args.crash_every > 0 and args.crash_down >= 0):
        print("uwgen emulate: --crash-every must be > 0 and --crash-down >= 0", file=sys.stderr)
        return EXIT_USAGE
    return _serve(scenario, args.duration, args.crash_every, args.crash_down)


def split_ports(args: argparse.Namespace) -> argparse.Namespace:
    """`--ports 4900 4901 scen.yaml`: the ports, and the scenario file after them (argparse
    gives `--ports` every word up to the next option)."""
    from uwgen.emulator.scenario import ScenarioError

    if args.ports is None:
        return args
    ports, rest = [], []
    for word in args.ports:
        (rest if rest or not word.isdigit() else ports).append(word)
    if rest and (len(rest) > 1 or args.scenario is not None):
        raise ScenarioError(f"--ports: expected port numbers, got {' '.join(rest)}")
    bad = [p for p in ports if not 0 <= int(p) <= 65535]
    if bad:
        raise ScenarioError(f"--ports: {bad[0]} is not a TCP port (0..65535)")
    return argparse.Namespace(**{**vars(args), "ports": [int(p) for p in ports],
                                 "scenario": Path(rest[0]) if rest else args.scenario})


def build_scenario(args: argparse.Namespace):
    """The scenario from the YAML file (if any) with the command-line flags applied."""
    from dataclasses import replace

    from uwgen.emulator.scenario import NodeSpec, Scenario, ScenarioError, TdmaSpec, \
        load_scenario

    args = split_ports(args)

    if args.wind is not None and len(args.wind) != 1:
        raise ScenarioError("--wind takes one value when running nodes "
                            "(several only with --pdr-sweep)")
    if args.manifest is not None:
        from uwgen.emulator.from_manifest import scenario_from_manifest
        if args.nodes is not None or args.ports is not None:
            raise ScenarioError("--nodes and --ports come from the manifest's sides with -m")
        spacing = args.distance if args.distance is not None else 1000.0
        base = scenario_from_manifest(args.manifest, args.scenario, spacing)
        args = argparse.Namespace(**{**vars(args), "distance": None,
                                     "period": _refuse(args.period, "--period"),
                                     "max_read_length": _refuse(args.max_read_length,
                                                                "--max-read-length")})
    else:
        base = load_scenario(args.scenario) if args.scenario else None
    changes: dict = {}
    for key in ("period", "max_read_length", "bitrate", "per", "seed"):
        value = getattr(args, key)
        if value is not None:
            changes[key] = value
    changes["snr"] = channel_model(args, base)
    if args.tdma is not None or args.guard is not None:
        tdma = base.tdma if base is not None and base.tdma is not None else TdmaSpec()
        if args.tdma is not None:
            tdma = replace(tdma, frame=args.tdma)
        if args.guard is not None:
            tdma = replace(tdma, guard=args.guard)
        changes["tdma"] = tdma
    node_flags = args.nodes is not None or args.ports is not None or args.distance is not None
    if base is None or node_flags:
        count = args.nodes if args.nodes is not None else (
            len(args.ports) if args.ports else (len(base.nodes) if base else 2))
        if count < 2:
            raise ScenarioError(f"--nodes must be at least 2, got {count}")
        ports = args.ports if args.ports is not None else [4000 + i for i in range(count)]
        if len(ports) != count:
            raise ScenarioError(f"--ports gives {len(ports)} ports for {count} nodes")
        spacing = args.distance if args.distance is not None else 1000.0
        if base is not None and not (args.nodes or args.distance):
            # Only --ports given: keep the file's nodes, move them to the new ports.
            if len(ports) != len(base.nodes):
                raise ScenarioError(f"--ports gives {len(ports)} ports for the "
                                    f"{len(base.nodes)} nodes of {args.scenario}")
            nodes = [replace(n, port=p) for n, p in zip(base.nodes, ports)]
        else:
            nodes = [NodeSpec(f"node{i + 1}", port=ports[i], position=(i * spacing, 0.0, 0.0))
                     for i in range(count)]
        changes["nodes"] = nodes
    if base is None:
        return Scenario(**changes)
    return replace(base, **changes)


def channel_model(args: argparse.Namespace, base):
    """The SNR model: --phy's if given, else the scenario file's `snr:`, else the default
    PHY (DESERT's stock scenario's); --wind applies to it."""
    from dataclasses import replace

    from uwgen.emulator.physics import phy
    from uwgen.emulator.scenario import ScenarioError

    if args.phy is not None:
        snr = phy(args.phy)
    elif base is not None and base.snr is not None:
        snr = base.snr
    else:
        snr = phy(DEFAULT_PHY)
    if args.wind is not None:
        if snr is None:
            raise ScenarioError("--wind needs an SNR model: --phy desert-stock or --phy thesis")
        try:
            snr = replace(snr, wind=args.wind[0])
        except ValueError as exc:
            raise ScenarioError(f"--wind: {exc}") from None
    return snr


def phy_name(snr) -> str:
    """How the log names a scenario's SNR model: its PHY's name, with the wind if not 0."""
    from dataclasses import replace
    if snr is None:
        return "no SNR losses (--phy none)"
    name = next((n for n, m in PHYS.items() if m is not None and replace(snr, wind=m.wind) == m), None)
    wind = f", wind {snr.wind:g} m/s" if snr.wind else ""
    return f"SNR model {name}{wind}" if name else f"SNR model of the scenario{wind}"


def _refuse(value, flag: str):
    from uwgen.emulator.scenario import ScenarioError
    if value is not None:
        raise ScenarioError(f"{flag} comes from the manifest's link settings with -m")
    return None


def _serve(scenario, duration: float | None, crash_every: float | None = None,
           crash_down: float = 1.0) -> int:
    from uwgen.emulator.server import Emulator, EmulatorError

    emu = Emulator(scenario)
    try:
        emu.start()
    except EmulatorError as exc:   # a port taken: bad input, as every other error
        print(f"uwgen emulate: {exc}", file=sys.stderr)
        return EXIT_USAGE
    feeds = None
    if any(n.pose_topic is not None for n in scenario.nodes):
        from uwgen.emulator.ros_pose import PoseFeedError, PoseFeeds
        try:
            feeds = PoseFeeds(emu, scenario).start()
        except PoseFeedError as exc:
            emu.stop()
            print(f"uwgen emulate: {exc}", file=sys.stderr)
            return EXIT_FAILED
    crasher = None
    if crash_every is not None:
        from uwgen.emulator.chaos import Crasher
        crasher = Crasher(emu, crash_every, crash_down, scenario.seed).start()
        log.info("emulator: DESERT will crash at random, every %.3g s on average, down %.3g s",
                 crash_every, crash_down)
    mode = "TDMA" if scenario.tdma else "CSMA-ALOHA"
    channel = phy_name(scenario.snr)
    periods = sorted({scenario.period_of(n) for n in scenario.names()})
    lengths = sorted({scenario.max_read_length_of(n) for n in scenario.names()})
    log.info("emulating %d DESERT nodes (%s): period %s s, max_read_length %s, %g bit/s, %s, "
             "%s, per %.3g, seed %d", len(scenario.nodes), ", ".join(scenario.names()),
             "/".join(f"{p:.3g}" for p in periods), "/".join(map(str, lengths)),
             scenario.bitrate, mode, channel, scenario.per, scenario.seed)
    stop = threading.Event()
    previous = {}

    def on_signal(signum, _frame) -> None:
        log.info("emulator: %s received, stopping", signal.Signals(signum).name)
        stop.set()

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, on_signal)
    # Ports go to stdout (one line per node) once the signals are handled, so a script
    # can read them and stop the emulator at any moment after.
    for name, port in emu.ports().items():
        print(f"{name} 127.0.0.1:{port}", flush=True)
    try:
        stop.wait(duration)
    except KeyboardInterrupt:
        pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if crasher is not None:
            crasher.stop()
        if feeds is not None:
            feeds.stop()
        emu.stop()
    print(format_counters(emu.all_counters()), flush=True)
    if crasher is not None:
        print(f"DESERT crashed {crasher.crashes} times (simulated, --crash-every)", flush=True)
    return 0


def format_counters(counters: dict[str, dict[str, int]]) -> str:
    """Per-node counters as a table (one row per node)."""
    names = list(counters)
    width = max(len("node"), *(len(n) for n in names))
    cols = COUNTER_COLUMNS
    header = "node".ljust(width) + " " + " ".join(c.rjust(max(len(c), 6)) for c in cols)
    lines = [header]
    for name in names:
        row = counters[name]
        lines.append(name.ljust(width) + " " + " ".join(
            str(row.get(c, 0)).rjust(max(len(c), 6)) for c in cols))
    return "\n".join(lines)


def _sweep(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from uwgen.emulator.physics import phy
    from uwgen.emulator.sweep import DEFAULT_WINDS, format_table, pdr_sweep, plot

    winds = args.wind if args.wind is not None else DEFAULT_WINDS
    if args.packets < 1:
        print("uwgen emulate: --packets must be at least 1", file=sys.stderr)
        return EXIT_USAGE
    base = phy(args.phy or DEFAULT_PHY)
    if base is None:
        print("uwgen emulate: --pdr-sweep needs an SNR model (--phy desert-stock or thesis)",
              file=sys.stderr)
        return EXIT_USAGE
    try:
        for w in winds:
            replace(base, wind=w)
    except ValueError as exc:
        print(f"uwgen emulate: --wind: {exc}", file=sys.stderr)
        return EXIT_USAGE
    seed = args.seed if args.seed is not None else 1
    result = pdr_sweep(winds=winds, packets=args.packets, seed=seed, base=base,
                       payload=args.max_read_length or 64)
    print(format_table(result), flush=True)
    if args.plot is not None:
        path = plot(result, args.plot)
        log.info("PDR sweep plot saved to %s", path)
    return 0
