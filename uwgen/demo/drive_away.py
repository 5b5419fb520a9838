"""`uwgen demo --drive-away`: the vehicle drives away from the surface station until the
acoustic link fades; the report gives delivery ratio and latency against distance.

The demo's usual processes run (two bridges, the vehicle simulator, the operator driving
laps of its square at 10 Hz, the vehicle reporting its pose), but the emulated vehicle
node follows waypoints: it waits at the start distance while the operator sets up, then
moves off in a straight line, time-lapsed (about 100 m/s) so that the whole fade fits in a
minute and a half. Every cmd_vel the operator published and every pose the vehicle
published is placed at the distance the vehicle was at when it was published, and
counted as delivered or not; the plot (`drive-away.png`) shows delivery ratio and
latency per distance bin for both directions.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from statistics import median

from uwgen import pngplot

HOLD = 15.0          # seconds at the start distance (bridges connect, services, teleport)


@dataclass
class Bin:
    start: float                     # metres
    width: float
    sent: int = 0
    delivered: int = 0
    latencies: list = field(default_factory=list)

    @property
    def ratio(self) -> float | None:
        return self.delivered / self.sent if self.sent else None

    @property
    def latency(self) -> float | None:
        return median(self.latencies) if self.latencies else None


def by_distance(sent: list[tuple[object, float]], received: list[tuple[object, float]],
                distance_at, width: float = 500.0) -> list[Bin]:
    """Bins of `width` metres: how many (key, time) messages were sent while the vehicle was
    in the bin, how many of those were received (same key, later), and their latencies.
    Keys sent more than once are ambiguous and left out."""
    counts: dict[object, int] = {}
    for key, _ in sent:
        counts[key] = counts.get(key, 0) + 1
    first_rx: dict[object, float] = {}
    for key, t in received:
        first_rx.setdefault(key, t)
    bins: dict[int, Bin] = {}
    for key, t in sent:
        if counts[key] != 1:
            continue
        i = int(distance_at(t) // width)
        b = bins.setdefault(i, Bin(i * width, width))
        b.sent += 1
        rx = first_rx.get(key)
        if rx is not None and rx >= t:
            b.delivered += 1
            b.latencies.append(rx - t)
    return [bins[i] for i in sorted(bins)]


def format_bins(name: str, bins: list[Bin]) -> str:
    lines = [f"{name}: delivery and latency against distance",
             f"  {'distance (km)':>14} {'sent':>5} {'delivered':>9} {'ratio':>6} {'median latency':>15}"]
    for b in bins:
        lat = f"{b.latency:.2f} s" if b.latency is not None else "-"
        lines.append(f"  {b.start / 1000:6.1f}-{(b.start + b.width) / 1000:<6.1f} {b.sent:5d} "
                     f"{b.delivered:9d} {b.ratio:6.2f} {lat:>15}")
    return "\n".join(lines)


def plot(curves: dict[str, list[Bin]], path: Path, title: str) -> Path:
    plt = pngplot.pyplot()

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), dpi=110, sharex=True)
    for (name, bins), color in zip(curves.items(), ("tab:blue", "tab:orange")):
        mids = [(b.start + b.width / 2) / 1000 for b in bins]
        top.plot(mids, [b.ratio for b in bins], "o-", color=color, label=name)
        pts = [(m, b.latency) for m, b in zip(mids, bins) if b.latency is not None]
        if pts:
            bottom.plot(*zip(*pts), "o-", color=color, label=name)
    top.set_ylabel("delivery ratio")
    top.set_ylim(-0.05, 1.05)
    bottom.set_ylabel("median latency (s)")
    bottom.set_xlabel("distance from the surface station when published (km)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    top.set_title(title, fontsize=10)
    fig.tight_layout()
    return pngplot.save(fig, path)


def channel(phy_name: str, wind: float):
    """The SNR model the drive runs through: the named PHY (the demo's --phy) at `wind`."""
    from dataclasses import replace

    from uwgen.emulator.physics import phy
    model = phy(phy_name)
    if model is None:
        raise ValueError(f"--drive-away needs a channel that fades: --phy {phy_name} has no SNR losses")
    return replace(model, wind=wind)


def expected_fade(snr) -> tuple[float, float]:
    """(metres up to which one-way delivery is full, metres from which nothing arrives) of
    `snr` (simulated, one way, 200 packets per 250 m): where the drive's checks look."""
    from uwgen.emulator.sweep import DEFAULT_DISTANCES, full_delivery_range, pdr_at, zero_delivery_distance
    points = [pdr_at(d, snr, packets=200, seed=1 + i) for i, d in enumerate(DEFAULT_DISTANCES)]
    return full_delivery_range(points), zero_delivery_distance(points) or DEFAULT_DISTANCES[-1]


def scenario(start: float, end: float, duration: float, wind: float, seed: int,
             phy_name: str = "desert-stock"):
    from uwgen.emulator import NodeSpec, Scenario
    track = ((0.0, start, 0.0, 0.0), (HOLD, start, 0.0, 0.0), (HOLD + duration, end, 0.0, 0.0))
    return Scenario(nodes=[NodeSpec("surface", position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", dest="surface", waypoints=track)],
                    period=0.2, max_read_length=64, bitrate=4800.0, seed=seed,
                    snr=channel(phy_name, wind))


def run(args: argparse.Namespace) -> int:
    import contextlib

    from uwgen.demo.processes import (GENERATED, PACKAGE, Proc, _env, domains, ended_early, failures,
                                      network_key, stop_all, wait_for)
    from uwgen.typesupport import BuildError, ensure_interfaces
    from uwgen.demo.records import read_records
    from uwgen.demo.report import POSE_KEY_STEPS
    from uwgen.emulator import run_emulator

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.json*"):
        old.unlink()
    if not (GENERATED / PACKAGE / "bridge_surface.py").exists():
        print(f"uwgen demo: {GENERATED / PACKAGE} has no bridge modules: run `uwgen build`",
              file=sys.stderr)
        return 1
    try:
        iface = ensure_interfaces(GENERATED.parent / "msg_samples" / "turtlesim")
    except BuildError as exc:
        print(f"uwgen demo: turtlesim's interfaces are not available to rclpy: {exc}",
              file=sys.stderr)
        return 1
    keys = contextlib.ExitStack()
    key = network_key(keys, out, lambda *a: None if args.quiet else print(*a),
                      getattr(args, "key_file", None))
    if key is False:
        return 1
    key_args = key.bridge_args() if key else []
    start, end, duration = args.distance, args.drive_to, args.drive_time
    phy_name = getattr(args, "phy", "desert-stock")
    try:
        scen = scenario(start, end, duration, args.wind, args.seed, phy_name)
    except ValueError as exc:
        print(f"uwgen demo: {exc}", file=sys.stderr)
        return 2
    full, none = expected_fade(scen.snr)
    speed = (end - start) / duration
    print(f"uwgen demo --drive-away: the vehicle waits {HOLD:g} s at {start:g} m, then drives "
          f"away to {end / 1000:g} km at {speed:.0f} m/s (time-lapse), PHY {phy_name}, wind "
          f"{args.wind:g} m/s (one way: full delivery to {full / 1000:g} km, none from "
          f"{none / 1000:g} km)")
    vdom, sdom = domains()
    py = sys.executable
    procs: list = []
    with keys, run_emulator(scen) as emu:
        t0 = time.time()                      # emulator time 0, on the records' clock
        ports = {n: emu.port(n) for n in ("surface", "vehicle")}
        venv = _env(vdom, [str(GENERATED)], iface)
        senv = _env(sdom, [str(GENERATED)], iface)
        try:
            for side, env in (("vehicle", venv), ("surface", senv)):
                procs.append(Proc(f"bridge_{side}", [
                    py, "-m", f"{PACKAGE}.bridge_{side}", "--port", str(ports[side]),
                    "--stats-file", str(out / f"bridge_{side}.json"), *key_args], env, out,
                    not args.quiet))
            procs.append(Proc("vehicle", [py, "-m", "uwgen.demo.vehicle", "--record",
                                          str(out / "vehicle.jsonl")], venv, out, not args.quiet))
            operator = Proc("operator", [py, "-m", "uwgen.demo.operator", "--record",
                                         str(out / "operator.jsonl"), "--square-size", str(args.square_size),
                                         "--laps", "100", "--max-drive", str(HOLD + duration)],
                            senv, out, not args.quiet)
            procs.append(operator)
            try:
                dead = wait_for([operator], HOLD + duration + 15.0, procs[:-1])
                if dead is not None:
                    print(ended_early(dead), file=sys.stderr)
            except subprocess.TimeoutExpired:
                pass
        finally:
            codes = stop_all(procs)
            counters = emu.all_counters()
    (out / "emulator.json").write_text(json.dumps({"nodes": counters, "ports": ports}, indent=1))

    def distance_at(t_wall: float) -> float:
        x, y, z = scen.position_at("vehicle", t_wall - t0)
        return (x * x + y * y + z * z) ** 0.5

    op = list(read_records(out / "operator.jsonl"))
    veh = list(read_records(out / "vehicle.jsonl"))
    cmd = by_distance([(r["k"], r["t"]) for r in op if r.get("ev") == "cmd"],
                      [(r["k"], r["t"]) for r in veh if r.get("ev") == "cmd"], distance_at)
    def key(r):          # poses cross quantized: match on the manifest's grid (demo report)
        return tuple(round(r[k] / step) for k, step in POSE_KEY_STEPS)
    pose = by_distance([(key(r), r["t"]) for r in veh if r.get("ev") == "pose"],
                       [(key(r), r["t"]) for r in op if r.get("ev") == "pose_rx"], distance_at)
    print("\nratios are of published messages: the link keeps only the latest cmd_vel (10 Hz) "
          "and pose and sends one 64 B packet per 0.2 s each way")
    print(format_bins("cmd_vel (surface -> vehicle)", cmd))
    print(format_bins("pose (vehicle -> surface)", pose))
    title = (f"uwgen demo --drive-away: 64 B / 0.2 s at 4800 bit/s, PHY {phy_name}, "
             f"wind {args.wind:g} m/s")
    curves = {"cmd_vel (surface → vehicle)": cmd, "pose (vehicle → surface)": pose}
    png = plot(curves, out / "drive-away.png", title)
    print(f"plot: {png}")
    if args.docs:
        plot(curves, GENERATED.parent / "docs" / "drive-away.png", title)
        print("plot: docs/drive-away.png")
    crashed = failures(codes)
    if crashed:
        print(f"uwgen demo: processes ended badly: {crashed} (see their logs)", file=sys.stderr)
        return 1
    # Ratios are of published messages: the link keeps only the latest cmd_vel and pose
    # and carries one packet per 0.2 s each way, so even near the station it is well under 1.
    near = [b for b in cmd + pose if b.start + b.width <= full and b.sent]
    far = [b for b in cmd + pose if b.start >= none + 500.0 and b.sent]
    if not near or min(b.ratio for b in near) == 0.0:
        print("uwgen demo: the link did not work near the surface station", file=sys.stderr)
        return 1
    if any(b.delivered for b in far):
        print("uwgen demo: the link did not fade far away", file=sys.stderr)
        return 1
    print("the link carried both directions up to the fade and nothing beyond it")
    return 0
