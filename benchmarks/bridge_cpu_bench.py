#!/usr/bin/env python3
"""Bridge CPU benchmark: a bridge against a bare rclpy node on the same topic, same run.

    .venv/bin/python benchmarks/bridge_cpu_bench.py [--seconds 8] [--rates 1000 5000]
        [--baseline /work/main/.venv/bin/python] [--record [--repeat 3]]

Runs the emulator, a surface and a vehicle bridge (`uwgen bridge`, each in its own process
and ROS domain) and, in the surface domain, two bare rclpy nodes that subscribe to the same
Twist topic and do nothing else (each its own process): one on SingleThreadedExecutor (as
the bridge), one on rclpy's experimental EventsExecutor. This process publishes Twist at
each rate, and a high-priority Header topic twice a second whose latency it measures on
the vehicle side. It prints the CPU time per message of the surface bridge and of both bare
nodes (from /proc, over the same seconds), the bridge's ratio to the bare
SingleThreadedExecutor node, the rate one core would carry (messages per CPU second), the
bridge's RSS and the high-priority topic's latency. The link is the demo's (64-byte packets
every 0.2 s): cmd_vel is latest-only, so nearly every message is superseded, as in the
field (the bridge polls its subscription every 20 ms and deserializes and encodes only the
newest, uwgen.bridge.polling); /alert is fifo, taken on executor wake-ups. (The bridge itself cannot run on Jazzy's EventsExecutor: it refuses guard
conditions, "Guard conditions not supported", and the bridge wakes its executor with one.)
With --baseline PYTHON, the surface bridge of another uwgen checkout (that interpreter's,
e.g. main's venv, with a package built by its own `uwgen build`) is measured too, in turns
with this one's against the same bare nodes: same-run ratios of before and after. With --record, this checkout's bridge is measured a
second time in turn with `--record` (every packet, every message taken and its status into an
MCAP file, uwgen.bridge.recorder): the `record +%` column is its extra CPU per message over the
unrecorded run just before it, `rec KiB` the file it wrote; with --repeat N each rate's
pair of runs is repeated N times and the median of the pairs' ratios is printed under the
table (a shared machine's load moves single runs by more than recording costs).
"""
from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Header

from uwgen import tether

ROOT = Path(__file__).resolve().parents[1]
UWGEN = [sys.executable, "-m", "uwgen.cli"]
TICK = os.sysconf("SC_CLK_TCK")

MANIFEST = """\
network: cpubench
package: uwgen_cpubench
sides:
  surface: {{port: {p0}, link: {{max_read_length: 64, period: 0.2}}}}
  vehicle: {{port: {p1}, link: {{max_read_length: 64, period: 0.2}}}}
topics:
  - {{name: /cmd_vel, id: 4, type: geometry_msgs/msg/Twist, publisher: surface, queue: latest, priority: 1}}
  - {{name: /alert, id: 5, type: std_msgs/msg/Header, publisher: surface, queue: fifo, depth: 4,
     ttl: 30, priority: 100}}
"""

BARE = textwrap.dedent("""
    import rclpy, sys
    from geometry_msgs.msg import Twist
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    rclpy.init()
    node = rclpy.create_node("bare_subscriber_" + sys.argv[1])
    node.create_subscription(Twist, "/cmd_vel", lambda m: None, 10)
    ex = EventsExecutor() if sys.argv[1] == "events" else SingleThreadedExecutor()
    ex.add_node(node)
    print("ready", flush=True)
    try:
        ex.spin()
    except BaseException:
        pass
""")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def ros_env(domain: int, **extra) -> dict:
    return {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "PYTHONUNBUFFERED": "1", **extra}


class Side:
    """An rclpy context in one domain of this process, spun in a thread."""

    def __init__(self, domain: int):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(f"bench_{domain}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        threading.Thread(target=self._spin, daemon=True).start()

    def _spin(self):
        try:
            self.executor.spin()
        except BaseException:
            pass

    def close(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def publish_at(pub, rate: float, seconds: float) -> int:
    """Publish Twist at `rate` for `seconds` (in 2 ms bursts); return how many."""
    msg, sent, start = Twist(), 0, time.monotonic()
    while (now := time.monotonic()) - start < seconds:
        due = int((now - start) * rate)
        while sent < due:
            msg.linear.x = sent * 1e-3
            pub.publish(msg)
            sent += 1
        time.sleep(0.002)
    return sent


def measure(python, package_dir, rate, seconds, bares, twist_pub, alert_pub, latencies, domain, manifest,
            record=None):
    """Start the surface bridge of `python`'s uwgen, publish at `rate`, and return its row
    (`record`: the bridge records to this MCAP file)."""
    bridge = tether.popen([python, "-m", "uwgen.cli", "--quiet", "bridge", "-m", str(manifest),
                           "--side", "surface", "--status-period", "0", "--package-dir", str(package_dir),
                           *(["--record", str(record)] if record else [])],
                          env=ros_env(domain), cwd=manifest.parent)
    try:
        time.sleep(4.0)                                  # discovery, link up
        watched = {"bridge": bridge, **bares}
        stop = threading.Event()

        def alerts():
            while not stop.wait(0.5):
                now = time.time()
                alert_pub.publish(Header(stamp=Time(sec=int(now), nanosec=int(now % 1 * 1e9))))
        publish_at(twist_pub, rate, 1.0)                 # warm up
        latencies.clear()
        threading.Thread(target=alerts, daemon=True).start()
        cpu = {k: cpu_seconds(p.pid) for k, p in watched.items()}
        sent = publish_at(twist_pub, rate, seconds)
        cpu = {k: cpu_seconds(p.pid) - cpu[k] for k, p in watched.items()}
        rss = rss_mib(bridge.pid)
        time.sleep(2.0)                                  # the last alerts arrive
        stop.set()
    finally:
        bridge.terminate()
        bridge.wait(10)
    lat = sorted(latencies)
    p95 = lat[int(0.95 * (len(lat) - 1))] if lat else float("nan")
    per = {k: c / sent * 1e6 for k, c in cpu.items()}
    return (sent, per["bridge"], per["single"], per["events"], cpu["bridge"] / max(cpu["single"], 1e-9),
            sent / max(cpu["bridge"], 1e-9), rss, statistics.median(lat) if lat else float("nan"), p95, len(lat))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--rates", type=float, nargs="+", default=[1000.0, 5000.0])
    parser.add_argument("--baseline", metavar="PYTHON", help="also measure the bridge of this interpreter's uwgen")
    parser.add_argument("--domain", type=int, default=None, metavar="N",
                        help="ROS domains N and N+1 (default: 40 + pid %% 150)")
    parser.add_argument("--record", action="store_true",
                        help="also measure this checkout's bridge recording to an MCAP file")
    parser.add_argument("--repeat", type=int, default=1, metavar="N",
                        help="measure each rate N times (default 1)")
    args = parser.parse_args()

    base = 40 + os.getpid() % 150 if args.domain is None else args.domain
    d_surface, d_vehicle = base, base + 1
    procs: list[subprocess.Popen] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        manifest = root / "uwgen.yaml"
        manifest.write_text(MANIFEST.format(p0=free_port(), p1=free_port()))
        pythons = {"this": sys.executable, **({"baseline": args.baseline} if args.baseline else {})}
        for label, python in pythons.items():
            subprocess.run([python, "-m", "uwgen.cli", "--quiet", "build", "-m", str(manifest), "-o",
                            str(root / label / "uwgen_cpubench")], check=True, cwd=root)
        procs.append(tether.popen([*UWGEN, "--quiet", "emulate", "-m", str(manifest), "--distance", "300"],
                                  cwd=root, stdout=subprocess.DEVNULL))
        time.sleep(1.5)
        bares = {}
        for kind in ("single", "events"):
            bares[kind] = tether.popen([sys.executable, "-c", BARE, kind], env=ros_env(d_surface),
                                       stdout=subprocess.PIPE, text=True)
            procs.append(bares[kind])
            bares[kind].stdout.readline()
        vehicle = tether.popen([*UWGEN, "--quiet", "bridge", "-m", str(manifest), "--side", "vehicle",
                                "--package-dir", str(root / "this")], env=ros_env(d_vehicle), cwd=root)
        procs.append(vehicle)
        surface_side, vehicle_side = Side(d_surface), Side(d_vehicle)
        twist_pub = surface_side.node.create_publisher(Twist, "/cmd_vel", 10)
        alert_pub = surface_side.node.create_publisher(Header, "/alert", 10)
        latencies: list[float] = []
        vehicle_side.node.create_subscription(
            Header, "/alert", lambda h: latencies.append(time.time() - h.stamp.sec - h.stamp.nanosec * 1e-9), 10)
        rows = []
        sizes: dict[float, float] = {}
        try:
            for rate in [r for r in args.rates for _ in range(args.repeat)]:
                for label, python in pythons.items():
                    rows.append((label, rate, *measure(python, root / label, rate, args.seconds, bares,
                                                       twist_pub, alert_pub, latencies, d_surface, manifest)))
                if args.record:
                    rec = root / f"record-{rate:.0f}.mcap"
                    rows.append(("record", rate, *measure(sys.executable, root / "this", rate, args.seconds,
                                                          bares, twist_pub, alert_pub, latencies, d_surface,
                                                          manifest, record=rec)))
                    sizes[rate] = sum(f.stat().st_size for f in root.glob(f"record-{rate:.0f}*.mcap")) / 1024
        finally:
            for p in reversed(procs):
                if p.poll() is None:
                    p.terminate()
                    try:
                        p.wait(10)
                    except subprocess.TimeoutExpired:
                        p.kill()
            surface_side.close()
            vehicle_side.close()

    extra = f"{'record +%':>10}{'rec KiB':>8}" if args.record else ""
    print(f"{'bridge':<9}{'rate/s':>7}{'msgs':>7}{'bridge us/msg':>14}{'bare us/msg':>12}{'bare events':>12}"
          f"{'ratio':>7}{'msg/s at 1 core':>16}{'RSS MiB':>8}{'alert p50 s':>12}{'p95 s':>7}{'n':>4}{extra}")
    plain, extra_cpu, extra_ratio = None, {}, {}
    for label, rate, sent, ub, us, ue, ratio, core, rss, p50, p95, n in rows:
        more = ""
        if label == "this":
            plain = (ub, ratio)
        if label == "record":
            extra_cpu.setdefault(rate, []).append((ub / plain[0] - 1) * 100)
            extra_ratio.setdefault(rate, []).append((ratio / plain[1] - 1) * 100)
            more = f"{extra_cpu[rate][-1]:>+10.1f}{sizes.get(rate, 0):>8.0f}"
        print(f"{label:<9}{rate:>7.0f}{sent:>7}{ub:>14.1f}{us:>12.1f}{ue:>12.1f}{ratio:>7.2f}{core:>16.0f}{rss:>8.1f}"
              f"{p50:>12.2f}{p95:>7.2f}{n:>4}{more}")
    print("ratio: bridge CPU per message / CPU per message of the bare SingleThreadedExecutor node over the "
          "same seconds; msg/s at 1 core: messages per CPU second of the bridge (extrapolated); alert: "
          "latency of the priority-100 topic published twice a second meanwhile"
          + ("; record +%: the recording bridge's CPU per message over the same rate's plain run "
             "(`this` just before), rec KiB: what it wrote" if args.record else ""))
    for rate, extra in extra_cpu.items():
        by_ratio = extra_ratio[rate]
        print(f"recording at {rate:.0f} msg/s: {statistics.median(extra):+.1f} % bridge CPU per message "
              f"(median of {len(extra)} pairs: {', '.join(f'{x:+.1f}' for x in extra)}); "
              f"{statistics.median(by_ratio):+.1f} % in the bridge's ratio to the bare node over the "
              f"same seconds ({', '.join(f'{x:+.1f}' for x in by_ratio)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
