"""`uwgen demo --vehicles N`: one surface station drives N simulated turtles over one channel.

What runs (msg_samples/fleet/uwgen.yaml, built to generated/uwgen_fleet_demo):

    emulated DESERT network: surface node, and one node per vehicle `--distance` m away
    surface domain: one scripted operator per vehicle (its namespace, its own square)
                    <-> bridge_surface <-> DESERT node "surface"
    vehicle k's domain: vehicle simulator under /auvk <-> bridge_auvk <-> DESERT node "auvk"

Each vehicle is a side of the manifest's `fleet:` section: its commands are its own ids,
its telemetry comes under its namespace. The channel is shared as the manifest's `mac:`
section says (UW/TDMA, one slot per side in the fleet's order; `--mac turns` has the
surface grant each vehicle its turn instead, `--mac none` is stock CSMA-ALOHA), for the
bridges and the emulator alike. The report has one row per vehicle; the demo fails unless
every vehicle followed its square (docs/demo.md).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import subprocess
import sys
import time
from pathlib import Path

from uwgen.demo.processes import (GENERATED, ROOT, Proc, _env, domains, ended_early, failures,
                                  network_key, stop_all, wait_for)
from uwgen.demo.vehicle import CMD_TIMEOUT

PACKAGE = "uwgen_fleet_demo"
MANIFEST = ROOT / "msg_samples" / "fleet" / "uwgen.yaml"
MAX_VEHICLES = 3             # the vehicles msg_samples/fleet/uwgen.yaml declares
FOLLOW_TOLERANCE = 0.5       # metres between the reported path and the commanded square
SQUARE_GAP = 2.0             # metres between two vehicles' squares
TDMA_LAG = 0.5               # frames of commands the pilot counts on top of a pose (lag)
BITRATE = 4800.0
MRL = 64
SPREAD = math.radians(20)    # the vehicles' bearings from the surface, this far apart
PERIOD = 0.2                 # s between two packets of a side (DESERT's period_)
CALL_TIMEOUT = 24.0          # s the operator waits for a call (the manifest's 20 s + margin)
MAX_DRIVE = 420.0            # s the operators may take for their squares: commands arrive a
                             # frame apart and a turtle stops 1 s after its last one, so each
                             # moves about a third of the time
MIN_TIMEOUT = 600.0          # s the fleet demo waits for its operators at least (--timeout)


def fleet_mac(args: argparse.Namespace):
    """The MAC of bridges and emulator: the fleet manifest's (--mac manifest or tdma), the
    surface granting turns (--mac turns), or none."""
    from uwgen.manifest.mac import mac_of_file
    from uwgen.manifest.model import MacConfig
    base = mac_of_file(MANIFEST)
    mode = getattr(args, "mac", "manifest")
    if mode in ("manifest", "tdma") and (mode == "manifest" or base.mode == "tdma"):
        return base
    if mode == "turns":
        return MacConfig(mode="turns", bitrate=base.bitrate, range=args.distance, leader="surface")
    if mode == "tdma":
        raise ValueError(f"{MANIFEST} gives no TDMA to run (its mac is {base.mode})")
    return MacConfig(bitrate=base.bitrate)


def scenario(args: argparse.Namespace):
    from uwgen.emulator import BROADCAST, NodeSpec, Scenario
    from uwgen.emulator.physics import phy
    from uwgen.emulator.from_manifest import with_mac
    names = [f"auv{k}" for k in range(1, args.vehicles + 1)]
    mac = fleet_mac(args)
    nodes = [NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest=BROADCAST)]
    for k, name in enumerate(names):
        bearing = (k - (len(names) - 1) / 2) * SPREAD
        nodes.append(NodeSpec(name, port=0, position=(args.distance * math.cos(bearing),
                                                      args.distance * math.sin(bearing), 0.0),
                              dest="surface"))
    scen = Scenario(nodes=nodes, period=PERIOD, max_read_length=MRL, bitrate=BITRATE, per=args.per,
                    seed=args.seed, snr=phy(args.phy))
    return with_mac(scen, mac), names, mac


def run(args: argparse.Namespace, say, quiet: bool, out: Path, mac_text) -> int:
    """The fleet demo; `mac_text(mac)`: the MAC as the bridges' --mac takes it (the demo
    command's, which imports this module)."""
    from uwgen.demo.report import build_report, plot_paths
    from uwgen.emulator import run_emulator
    from uwgen.typesupport import BuildError, ensure_interfaces

    if args.desert or args.drive_away:
        print("uwgen demo: --vehicles runs on the emulator only (no --desert, no --drive-away)",
              file=sys.stderr)
        return 2
    if not (GENERATED / PACKAGE / "bridge_surface.py").exists():
        print(f"uwgen demo: {GENERATED / PACKAGE} has no bridge modules: run `uwgen build`", file=sys.stderr)
        return 1
    try:
        scen, names, mac = scenario(args)
    except ValueError as exc:
        print(f"uwgen demo: {exc}", file=sys.stderr)
        return 2
    say(f"uwgen demo: a surface station drives {len(names)} simulated vehicles over one emulated "
        "acoustic channel")
    try:
        iface = ensure_interfaces(ROOT / "msg_samples" / "turtlesim")
    except BuildError as exc:
        print(f"uwgen demo: turtlesim's interfaces are not available to rclpy: {exc}", file=sys.stderr)
        return 1
    keys = contextlib.ExitStack()
    key = network_key(keys, out, say, args.key_file)
    if key is False:
        return 1
    key_args = key.bridge_args() if key else []
    base = domains()[0]
    doms = {"surface": base, **{v: base + k for k, v in enumerate(names, 1)}}
    py = sys.executable
    procs: list[Proc] = []
    operators: list[Proc] = []
    t0 = time.monotonic()
    with keys, run_emulator(scen) as emu:
        say(f"  emulated DESERT nodes: surface and {', '.join(names)}, {args.distance:g} m from the "
            f"surface; {MRL} B every {PERIOD:g} s at {BITRATE:g} bit/s, PHY {args.phy}, packet "
            f"error rate {args.per:g}; the channel shared by {describe_fleet_mac(mac)}")
        say("  ROS domains: " + ", ".join(f"{n} {d}" for n, d in doms.items()) + f"; logs in {out}")
        envs = {n: _env(d, [str(GENERATED)], iface) for n, d in doms.items()}
        try:
            for side in [*names, "surface"]:
                procs.append(Proc(f"bridge_{side}", [
                    py, "-m", f"{PACKAGE}.bridge_{side}", "--port", str(emu.port(side)),
                    "--stats-file", str(out / f"bridge_{side}.json"), "--status-period", "5",
                    "--mac", mac_text(mac), *key_args], envs[side], out, not quiet))
            for k, v in enumerate(names):
                procs.append(Proc(f"vehicle_{v}", [py, "-m", "uwgen.demo.vehicle", "--namespace", f"/{v}",
                                                   "--record", str(out / f"vehicle_{v}.jsonl")],
                                  envs[v], out, not quiet))
            for k, v in enumerate(names):
                start = f"{2.0 + k * (args.square_size + SQUARE_GAP):g},2"
                op = Proc(f"operator_{v}", [
                    py, "-m", "uwgen.demo.operator", "--namespace", f"/{v}", "--start", start,
                    "--record", str(out / f"operator_{v}.jsonl"), "--square-size", str(args.square_size),
                    "--laps", str(args.laps), "--call-timeout", str(CALL_TIMEOUT), "--speed", "0.3",
                    "--turn", "0.5", "--lag", f"{lag(mac, len(names)):.2f}",
                    "--share", f"{min(1.0, CMD_TIMEOUT / lag(mac, len(names))):.2f}",
                    "--max-drive", str(MAX_DRIVE), "--service-wait", "60"],
                    envs["surface"], out, not quiet)
                procs.append(op)
                operators.append(op)
            try:
                dead = wait_for(operators, max(args.timeout, MIN_TIMEOUT),
                                [p for p in procs if p not in operators])
                if dead is not None:
                    print(ended_early(dead), file=sys.stderr)
            except subprocess.TimeoutExpired:
                late = ", ".join(op.name for op in operators if op.proc.poll() is None)
                print(f"uwgen demo: {late} did not finish in {args.timeout:g} s; stopping",
                      file=sys.stderr)
        finally:
            codes = stop_all(procs)
            counters = emu.all_counters()
    (out / "emulator.json").write_text(json.dumps({"nodes": counters}, indent=1))
    elapsed = time.monotonic() - t0
    reports = {v: build_report(out, v, f"/{v}") for v in names}
    print()
    print(format_fleet(reports, counters))
    for v, report in reports.items():
        plot_paths(report, out / f"demo-path-{v}.png",
                   f"uwgen demo, {v} of {len(names)}: {args.distance:g} m, PER {args.per:g}, mac {mac.mode}")
    print(f"plots: {out}/demo-path-auv*.png\nrun took {elapsed:.0f} s; logs in {out}")
    crashed = failures(codes)
    if crashed:
        print(f"uwgen demo: processes ended badly: {crashed} (see their logs)", file=sys.stderr)
        return 1
    problems = [f"{v}: {p}" for v, r in reports.items() for p in vehicle_problems(r)]
    if problems:
        print(f"uwgen demo: not every vehicle followed: {'; '.join(problems)}", file=sys.stderr)
        return 1
    worst = max(r.deviation_max for r in reports.values())
    print(f"every vehicle followed its commands: reported paths within {worst:.2f} m of their squares")
    return 0


def lag(mac, vehicles: int) -> float:
    """Seconds of commands the pilot counts on top of a pose (operator.Pilot): about one round
    of turns under turns; under TDMA half a frame. The bridges time their writes to their
    slots, so a vehicle's pose, sent in its own slot, already shows some of the commands of
    the surface's slot before it (all of them for the vehicles whose slots come last): a whole
    frame counted them twice, and the pilot turned back and forth at a corner. Half a frame
    finishes the square wherever the vehicle's slot is (tests/bridge/test_demo_parts.py)."""
    if mac.mode == "tdma":
        return TDMA_LAG * mac.frame
    if mac.mode == "turns":
        return 1.0 + 0.8 * vehicles
    return 1.0


def describe_fleet_mac(mac) -> str:
    if mac.mode == "tdma":
        return (f"UW/TDMA (frame {mac.frame:g} s, {len(mac.slots)} slots in the order "
                f"{', '.join(mac.slots)}, guard {mac.guard:g} s, max_packet_per_slot "
                f"{mac.max_packet_per_slot})")
    if mac.mode == "turns":
        return "turns the surface grants each vehicle in order, over CSMA-ALOHA"
    return "stock CSMA-ALOHA (no MAC of uwgen's)"


def vehicle_problems(report) -> list[str]:
    out = []
    if not report.topics[0].delivered:
        out.append("no command reached the vehicle")
    if not report.topics[1].delivered:
        out.append("no pose reached the surface")
    out += [f"every call of {s.name} failed" for s in report.services if not s.ok]
    if not any(m.get("status") == "succeeded" for m in report.missions):
        out.append("the mission action did not succeed")
    if report.deviation_max is None or report.deviation_max > FOLLOW_TOLERANCE:
        out.append(f"the reported path is not within {FOLLOW_TOLERANCE} m of the square")
    return out


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def format_fleet(reports: dict, counters: dict) -> str:
    """One row per vehicle: its commands and poses (delivered of published, latency p50),
    its calls, its mission, how closely it followed, and its verdict."""
    head = (f"{'vehicle':<8}{'cmd_vel':>12}{'p50 s':>7}{'pose':>12}{'p50 s':>7}{'calls ok':>10}"
            f"{'mission':>11}{'path max m':>11}  verdict")
    lines = [head, "-" * len(head)]
    for v, r in reports.items():
        cmd, pose = r.topics[0], r.topics[1]
        calls = sum(s.calls for s in r.services)
        ok = sum(s.ok for s in r.services)
        mission = next((m.get("status") for m in r.missions), "-")
        problems = vehicle_problems(r)
        lines.append(f"{v:<8}{f'{cmd.delivered}/{cmd.published}':>12}{_ms(cmd.p50):>7}"
                     f"{f'{pose.delivered}/{pose.published}':>12}{_ms(pose.p50):>7}"
                     f"{f'{ok}/{calls}':>10}{mission:>11}{_ms(r.deviation_max):>11}  "
                     + ("followed" if not problems else "; ".join(problems)))
    lost = {k: sum(c.get(k, 0) for c in counters.values())
            for k in ("lost_collision", "lost_per", "lost_snr")}
    sent = sum(c.get("packets_sent", 0) for c in counters.values())
    queue = max((c.get("max_queue_bytes", 0) for c in counters.values()), default=0)
    lines.append(f"channel: {sent} packets sent; lost to collisions {lost['lost_collision']}, to "
                 f"PER {lost['lost_per']}, to SNR {lost['lost_snr']}; most bytes waiting in a DESERT "
                 f"node {queue}")
    return "\n".join(lines)
