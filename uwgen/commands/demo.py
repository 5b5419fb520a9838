"""`uwgen demo`: a surface operator drives a simulated vehicle over an emulated acoustic link.

What runs (each ROS process on its own, the vehicle's and the surface's in two different
ROS domains, as on two computers; discovery stays on this machine):

    emulated DESERT network (in this process): surface node ----300 m---- vehicle node
    surface domain: scripted operator  <->  bridge_surface  <-> DESERT node "surface"
    vehicle domain: vehicle simulator  <->  bridge_vehicle  <-> DESERT node "vehicle"

The operator sets the pen and teleports the turtle (services), then drives a square with
10 Hz cmd_vel; the vehicle reports its pose, battery and log lines. At the end a table
per topic and service and a plot of the commanded and reported path are produced.
The link is secured as the manifest says (docs/security.md): both bridges get the network
key with --key-file; the demo creates it when missing (uwgen.demo.keys).
Everything is written to --out (default demo_output/); --docs also writes the plot to
docs/demo-path.png (and the recordings' plots to docs/demo-link.png). See docs/demo.md.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

from uwgen.argtypes import caller_path, number, whole
from uwgen.commands.options import old_spelling
from uwgen.emulator.from_manifest import with_mac
from uwgen.manifest.model import MacConfig
from uwgen.emulator.physics import DEFAULT_PHY, PHYS, phy
from uwgen.demo.processes import (DEMO_MANIFEST, GENERATED, PACKAGE, ROOT, Proc, _env, domains, ended_early,
                                  failures, network_key, stop_all, wait_for)

HELP = "run the demo: operator and vehicle simulator talking through two bridges over an emulated acoustic link"

EXIT_FAILED = 1     # the run failed (a process crashed, the vehicle did not follow)
EXIT_USAGE = 2      # bad input: an --out that cannot be written, an unusable key file
FOLLOW_TOLERANCE = 0.5   # metres between the reported path and the commanded square

log = logging.getLogger("uwgen.demo")


EPILOG = """\
ROS domains: the vehicle's processes run in ROS domain ROS_DOMAIN_ID (taken modulo 101; when
it is unset, 1 + this process's id modulo 100), the surface's in the next one, ROS_DOMAIN_ID + 1,
as on two computers; discovery stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
Both domains should be free of other ROS processes for the run.
Ports: the emulated DESERT nodes listen on 127.0.0.1, on two free TCP ports the system picks
(printed at start; the manifest's 4000 and 4001 are not used), and each bridge connects to its
node's; with --desert, the given HOST:PORTs instead. DDS uses the UDP ports of the two domains
(7400 + 250 x domain id, and a few above)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = EPILOG
    parser.add_argument("--out", type=caller_path, default=None,
                        help="folder for logs, records, stats and the plot (default demo_output/ "
                             "in the checkout, or in uwgen's cache if the checkout is read-only)")
    parser.add_argument("--desert", type=desert_endpoints, default=None, metavar="HOST:PORT,HOST:PORT",
                        help="run against a running DESERT instead of the emulator: the surface "
                             "node's and the vehicle's application sockets (the bridges use the "
                             "manifest's link settings, 64 B every 0.2 s)")
    parser.add_argument("--key-file", type=caller_path, default=None, metavar="PATH",
                        help="the network key both bridges use (created when missing; default: "
                             "the manifest's msg_samples/keys/demo.key, or in uwgen's cache if "
                             "the checkout is read-only); nothing else is kept beside it (no "
                             "state file: every start picks a new random epoch)")
    parser.add_argument("--no-record", action="store_true",
                        help="do not record the bridges (by default each writes bridge_<side>.mcap "
                             "in --out, summarised by `uwgen log` into link.png)")
    parser.add_argument("--docs", action="store_true",
                        help="also write the plots to docs/demo-path.png and docs/demo-link.png")
    parser.add_argument("--distance", type=number(1, 1e5), default=300.0, help="metres between the nodes")
    parser.add_argument("--per", type=number(0, 1), default=0.05,
                        help="packet error rate on top of collisions (default 0.05)")
    parser.add_argument("--phy", choices=tuple(PHYS), default=DEFAULT_PHY, metavar="NAME",
                        help=f"the emulated channel's SNR model: {', '.join(PHYS)} (default "
                             f"{DEFAULT_PHY}: DESERT's stock two-node scenario, delivery ends "
                             "near 3.8 km; see `uwgen emulate --help`)")
    parser.add_argument("--seed", type=whole(0, 2 ** 64 - 1), default=1, help="emulator random seed")
    parser.add_argument("--mac", choices=("manifest", "turns", "tdma", "none"), default="manifest",
                        help="how the two sides share the channel (docs/emulator.md, MACs): the "
                             "demo manifest's mac: section (default: turns, the surface grants "
                             "the vehicle its turn over stock CSMA-ALOHA), turns, tdma (DESERT's "
                             "UW/TDMA: --frame, --guard, --max-packet-per-slot) or none (stock "
                             "CSMA-ALOHA, packets of the two sides collide)")
    parser.add_argument("--bridge-mac", dest="bridge_mac", choices=("same", "none"), default="same",
                        help="for comparison: none makes the bridges write as if DESERT ran "
                             "CSMA-ALOHA whatever --mac says (a bridge unaware of the MAC); "
                             "default same")
    parser.add_argument("--frame", type=number(0.01, 3600), default=1.0, metavar="S",
                        help="with --mac tdma: frame_duration (default 1.0, 2 slots)")
    parser.add_argument("--guard", type=number(0, 3600), default=0.25, metavar="S",
                        help="with --mac tdma: guard_time (default 0.25, as DESERT's samples)")
    parser.add_argument("--max-packet-per-slot", dest="max_packet_per_slot", type=whole(1, 100000),
                        default=1000, metavar="N",
                        help="with --mac tdma: max_packet_per_slot (default 1000, as DESERT's "
                             "ROV sample)")
    parser.add_argument("--square-size", dest="square_size", type=number(0, 1e3, above=True), default=4.0,
                        metavar="M", help="length of a side of the square the operator drives, in metres")
    # --side is a manifest side everywhere else; it was this command's square size.
    old_spelling(parser, "--side", "--square-size", "square_size", "demo", type=number(0, 1e3, above=True))
    parser.add_argument("--laps", type=whole(1, 100), default=1, help="laps of the square")
    parser.add_argument("--vehicles", type=whole(1, 3), default=1, metavar="N",
                        help="vehicles to drive, each on its own square behind its own bridge "
                             "and DESERT node over one channel (default 1; 2 or 3: the fleet of "
                             "msg_samples/fleet/uwgen.yaml, uwgen.demo.fleet)")
    parser.add_argument("--timeout", type=number(1, 1e6), default=180.0,
                        help="give up if the operator has not finished after this many seconds")
    parser.add_argument("--quiet", dest="quiet_command", action="store_true",
                        help="print only the report and problems (node errors): no relayed node logs, no INFO "
                             "lines (same as `uwgen --quiet demo`)")
    away = parser.add_argument_group("drive away (uwgen.demo.drive_away)")
    away.add_argument("--drive-away", action="store_true",
                      help="the vehicle drives away from --distance until the link fades; plots "
                           "delivery ratio and latency against distance (drive-away.png)")
    away.add_argument("--drive-to", type=number(1, 1e5), default=10000.0, metavar="M",
                      help="with --drive-away: final distance in metres (default 10000)")
    away.add_argument("--drive-time", type=number(1, 1e5), default=75.0, metavar="S",
                      help="with --drive-away: seconds the drive takes (default 75, time-lapse)")
    away.add_argument("--wind", type=number(0, 100), default=0.0, metavar="M_S",
                      help="with --drive-away: wind speed of the SNR model (default 0)")


def demo_mac(args: argparse.Namespace):
    """The MAC both bridges and the emulator use: the demo manifest's, or the one --mac names
    (ValueError when the manifest's does not read)."""
    from dataclasses import replace

    from uwgen.manifest.mac import mac_of_file
    from uwgen.manifest.nodes import ManifestError
    try:
        base = mac_of_file(DEMO_MANIFEST)
    except ManifestError as exc:
        raise ValueError(str(exc)) from None
    slots = ("surface", "vehicle")
    if args.mac == "manifest":
        return base
    if args.mac == "tdma":
        return MacConfig(mode="tdma", bitrate=base.bitrate, range=args.distance, frame=args.frame,
                         guard=args.guard, slots=slots, max_packet_per_slot=args.max_packet_per_slot,
                         queue_size=10)
    if args.mac == "turns":
        return base if base.mode == "turns" else MacConfig(mode="turns", bitrate=base.bitrate,
                                                           range=args.distance, leader="surface")
    return replace(MacConfig(), bitrate=base.bitrate)


def mac_text(mac) -> str:
    """`mac` as the bridges' --mac takes it (the manifest's syntax, every key spelled out)."""
    keys = {"mode": mac.mode, "bitrate": mac.bitrate, "range": mac.range}
    if mac.mode == "tdma":
        keys.update(frame=mac.frame, guard=mac.guard, slots="[" + ", ".join(mac.slots) + "]",
                    max_packet_per_slot=mac.max_packet_per_slot, queue_size=mac.queue_size)
        if mac.weights:
            keys["weights"] = "{" + ", ".join(f"{s}: {w}" for s, w in mac.weights) + "}"
    if mac.mode == "turns":
        keys["leader"] = mac.leader
        if mac.packets:
            keys["packets"] = "{" + ", ".join(f"{s}: {n}" for s, n in mac.packets) + "}"
    return "{" + ", ".join(f"{k}: {v}" for k, v in keys.items()) + "}"


def describe_mac(mac) -> str:
    if mac.mode == "tdma":
        return (f"UW/TDMA (frame {mac.frame:g} s, 2 slots, guard {mac.guard:g} s, "
                f"max_packet_per_slot {mac.max_packet_per_slot}, queue_size {mac.queue_size})")
    if mac.mode == "turns":
        return f"turns led by {mac.leader} over CSMA-ALOHA"
    return "CSMA-ALOHA (no turns: the sides collide)"


def desert_endpoints(text: str) -> dict[str, tuple[str, int]]:
    """`HOST:PORT,HOST:PORT` -> {"surface": (host, port), "vehicle": (host, port)}."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: expected two HOST:PORT, the surface's then the vehicle's")
    out = {}
    for side, part in zip(("surface", "vehicle"), parts):
        host, sep, port = part.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise argparse.ArgumentTypeError(f"{part!r}: expected HOST:PORT with a port 1..65535")
        out[side] = (host.strip("[]"), int(port))
    return out


def default_out() -> Path:
    """demo_output/ in the checkout, or in uwgen's cache when the checkout is read-only."""
    if os.access(ROOT, os.W_OK):
        return ROOT / "demo_output"
    from uwgen.typesupport import cache_root
    return cache_root() / "demo_output"


class _given_desert:
    """Stands in for the emulator when the demo runs against a DESERT someone else started."""

    def __init__(self, endpoints):
        self.endpoints = endpoints

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def all_counters(self) -> dict:
        return {}   # a real DESERT's counters are not ours to read


def _unreachable(hp: tuple[str, int], timeout: float = 3.0) -> str | None:
    """Why nothing accepts a TCP connection at `hp` (None: something does)."""
    import socket
    try:
        with socket.create_connection(hp, timeout=timeout):
            return None
    except OSError as exc:
        return exc.strerror or str(exc)


def _endpoint(hp: tuple[str, int]) -> str:
    return f"{hp[0]}:{hp[1]}"


def _link_plot(out: Path, title: str, docs: bool) -> None:
    """The bridges' recordings: where they are, and their plots (uwgen log); with `docs`,
    also docs/demo-link.png."""
    from uwgen.fieldkit.plots import plot_summary
    from uwgen.fieldkit.reader import RecordingError, read_recordings
    from uwgen.fieldkit.summary import summarise
    files = sorted(out.glob("bridge_*.mcap"))
    try:
        summary = summarise(read_recordings(files))
    except RecordingError as exc:
        print(f"uwgen demo: the bridges' recordings are not readable: {exc}", file=sys.stderr)
        return
    plot = plot_summary(summary, out / "link.png", title)
    if docs:
        plot_summary(summary, ROOT / "docs" / "demo-link.png", title)
    print(f"recordings: {', '.join(f.name for f in files)} (`uwgen log {' '.join(str(f) for f in files)}` "
          f"prints this table from them); link plot: {plot}")


def run(args: argparse.Namespace) -> int:
    if getattr(args, "vehicles", 1) > 1 and (args.drive_away or args.desert):
        print("uwgen demo: --vehicles runs on the emulator only (no --desert, no --drive-away)",
              file=sys.stderr)
        return 2
    if getattr(args, "drive_away", False):
        args.out = args.out or default_out()
        args.quiet = args.quiet or getattr(args, "quiet_command", False)
        from uwgen.demo import drive_away
        return drive_away.run(args)
    from uwgen.typesupport import BuildError, ensure_interfaces
    from uwgen.demo.report import build_report, format_report, frame_sizes, plot_paths
    from uwgen.emulator import NodeSpec, Scenario, run_emulator

    quiet = args.quiet or getattr(args, "quiet_command", False)
    say = (lambda *a, **k: None) if quiet else print
    out: Path = args.out or default_out()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"uwgen demo: cannot write {out}: {exc.strerror}; give another folder with --out",
              file=sys.stderr)
        return EXIT_USAGE
    for old in (*out.glob("*.json*"), *out.glob("bridge_*.mcap")):
        old.unlink()
    if getattr(args, "vehicles", 1) > 1:
        from uwgen.demo import fleet
        return fleet.run(args, say, quiet, out, mac_text)
    if not (GENERATED / PACKAGE / "bridge_surface.py").exists():
        print(f"uwgen demo: {GENERATED / PACKAGE} has no bridge modules: run `uwgen build`", file=sys.stderr)
        return EXIT_FAILED
    if args.desert:
        unreachable = [f"{side} at {_endpoint(hp)} ({why})" for side, hp in args.desert.items()
                       if (why := _unreachable(hp))]
        if unreachable:
            print(f"uwgen demo: cannot reach the DESERT node of {'; '.join(unreachable)}: is DESERT "
                  "running, with its UW/APPLICATION socket there?", file=sys.stderr)
            return EXIT_FAILED
    where = "a running DESERT" if args.desert else "an emulated acoustic link"
    say(f"uwgen demo: a surface operator drives a simulated vehicle over {where}")
    try:
        iface = ensure_interfaces(ROOT / "msg_samples" / "turtlesim")
    except BuildError as exc:
        print(f"uwgen demo: turtlesim's interfaces are not available to rclpy: {exc}", file=sys.stderr)
        return EXIT_FAILED

    keys = contextlib.ExitStack()
    key = network_key(keys, out, say, args.key_file)
    if key is False:
        return EXIT_USAGE
    key_args = key.bridge_args() if key else []

    try:
        mac = demo_mac(args)
    except ValueError as exc:
        print(f"uwgen demo: {exc}", file=sys.stderr)
        return EXIT_FAILED
    scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle",
                                    slot=0),
                           NodeSpec("vehicle", port=0, position=(args.distance, 0.0, 0.0), dest="surface",
                                    slot=1)],
                    period=0.2, max_read_length=64, bitrate=4800.0, per=args.per, seed=args.seed,
                    snr=phy(args.phy))
    scen = with_mac(scen, mac)
    bridge_mac = mac if args.bridge_mac == "same" else MacConfig(bitrate=mac.bitrate)
    key_args = [*key_args, "--mac", mac_text(bridge_mac)]
    vdom, sdom = domains()
    py = sys.executable
    procs: list[Proc] = []
    t0 = time.monotonic()
    with keys, (_given_desert(args.desert) if args.desert else run_emulator(scen)) as emu:
        endpoints = args.desert or {n: ("127.0.0.1", emu.port(n)) for n in ("surface", "vehicle")}
        ports = {n: port for n, (_host, port) in endpoints.items()}
        if args.desert:
            say(f"  DESERT nodes: surface on {_endpoint(endpoints['surface'])}, vehicle on "
                f"{_endpoint(endpoints['vehicle'])} (not started by uwgen)")
        else:
            say(f"  emulated DESERT nodes: surface on 127.0.0.1:{ports['surface']}, vehicle on "
                f"127.0.0.1:{ports['vehicle']}, {args.distance:g} m apart, "
                f"{scen.max_read_length} B every {scen.period:g} s at {scen.bitrate:g} bit/s, "
                f"PHY {args.phy}, packet error rate {args.per:g} plus collisions, "
                f"{describe_mac(mac)}")
        say(f"  ROS domains: vehicle {vdom}, surface {sdom}; logs and records in {out}")
        venv = _env(vdom, [str(GENERATED)], iface)
        senv = _env(sdom, [str(GENERATED)], iface)
        try:
            for side, env in (("vehicle", venv), ("surface", senv)):
                procs.append(Proc(f"bridge_{side}", [
                    py, "-m", f"{PACKAGE}.bridge_{side}", "--host", endpoints[side][0],
                    "--port", str(ports[side]),
                    "--stats-file", str(out / f"bridge_{side}.json"), "--status-period", "5", *key_args,
                    *([] if args.no_record else ["--record", str(out / f"bridge_{side}.mcap")])],
                    env, out, not quiet))
            procs.append(Proc("vehicle", [py, "-m", "uwgen.demo.vehicle", "--record",
                                          str(out / "vehicle.jsonl")], venv, out, not quiet))
            operator = Proc("operator", [py, "-m", "uwgen.demo.operator", "--record",
                                         str(out / "operator.jsonl"), "--square-size", str(args.square_size),
                                         "--laps", str(args.laps)], senv, out, not quiet)
            procs.append(operator)
            try:
                dead = wait_for([operator], args.timeout, procs[:-1])
                if dead is not None:
                    print(ended_early(dead), file=sys.stderr)
            except subprocess.TimeoutExpired:
                print(f"uwgen demo: the operator did not finish in {args.timeout:g} s; stopping",
                      file=sys.stderr)
        finally:
            codes = stop_all(procs)
            counters = emu.all_counters()
    (out / "emulator.json").write_text(json.dumps({"nodes": counters, "ports": ports}, indent=1))
    elapsed = time.monotonic() - t0
    crashed = failures(codes)
    report = build_report(out)
    report.sizes = frame_sizes(DEMO_MANIFEST, [ROOT / "msg_samples"])
    print()
    print(format_report(report))
    title = (f"uwgen demo: DESERT at {_endpoint(endpoints['surface'])} and {_endpoint(endpoints['vehicle'])}"
             if args.desert else
             f"uwgen demo: {args.distance:g} m acoustic link, {scen.max_read_length} B / "
             f"{scen.period:g} s, PHY {args.phy}, PER {args.per:g}, mac {mac.mode}")
    plot = plot_paths(report, out / "demo-path.png", title)
    if args.docs:
        plot_paths(report, ROOT / "docs" / "demo-path.png", title)
        print("plot: docs/demo-path.png")
    print(f"plot: {plot}")
    if not args.no_record:
        _link_plot(out, title, args.docs)
    print(f"run took {elapsed:.0f} s; logs in {out}")
    if crashed:
        print(f"uwgen demo: processes ended badly: {crashed} (see their logs)", file=sys.stderr)
        return EXIT_FAILED
    problems = []
    if not report.topics[0].delivered:
        problems.append("no command reached the vehicle")
    if not report.topics[1].delivered:
        problems.append("no pose reached the surface")
    problems += [f"every call of {s.name} failed" for s in report.services if not s.ok]
    if report.deviation_max is None or report.deviation_max > FOLLOW_TOLERANCE:
        problems.append(f"the reported path is not within {FOLLOW_TOLERANCE} m of the square")
    if problems:
        print(f"uwgen demo: the vehicle did not follow: {'; '.join(problems)}", file=sys.stderr)
        return EXIT_FAILED
    print(f"the vehicle followed the commands: reported path within {report.deviation_max:.2f} m "
          "of the commanded square")
    return 0
