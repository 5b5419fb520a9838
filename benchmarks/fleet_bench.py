#!/usr/bin/env python3
"""Fleet benchmark: one surface and N vehicles on one emulated acoustic channel, each vehicle
behind its own bridge, against the same per-vehicle workload between two sides, same run.

    python benchmarks/fleet_bench.py [--vehicles 8] [--per 0.1] [--calls 13] [--goals 13]
                                     [--seed 5] [--mac tdma|turns|none] [--surface-weight 4]
                                     [--surface-packets 6]

The network is one manifest with a `fleet:` section (uwgen.manifest.fleet): each vehicle
carries 2 topics (telemetry from the vehicle every --every seconds, a command from the
surface every --cmd-every telemetry messages), 1 service (request and response carry one
int32: the manifest omits BasicTypes' 13 other fields) and 1 action, under its own namespace
and ids. Every side
is its own ROS domain (ROS_DOMAIN_ID and the ones after it) in this process; the surface
calls each vehicle's service and sends goals to its action, vehicle by vehicle in parallel.

The channel: 4800 bit/s, 64-byte packets (one every 0.2 s at most), vehicles on a 100 m
circle around the surface, --per packet error rate on top of collisions. The manifest's
`mac:` section shares it, for the bridges and the emulator alike: `tdma` is DESERT's UW/TDMA
(one slot per side in the fleet's turn order, a guard over a packet's air time and the
longest delay; each bridge writes no more than its slot drains; the surface, which carries
every vehicle's commands, gets a slot --surface-weight times a vehicle's, DESERT's manual
mode), `turns` the surface granting each vehicle its turn in order over stock CSMA-ALOHA
(--surface-packets a surface turn), `none` stock CSMA-ALOHA alone.

It prints one row per network (the fleet and the two-side reference): telemetry and commands
delivered (unique messages received over published), calls ok within their timeout with the
real response, goals ok with the real result, packets lost to collisions and to PER at the
emulator, the most bytes waiting in any DESERT node's queue, the MAC queue's high mark
(packets) and the packets' transit in DESERT (written to delivered; the worst node's p50
and p95). Goal (docs: fleets): on the
fleet at 10 % PER, telemetry >= 0.95 x (1 - PER), calls and goals >= 0.99.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from rclpy.action import ActionClient, ActionServer
from std_msgs.msg import String
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan, import_package
from uwgen.emulator import BROADCAST, NodeSpec, Scenario, run_emulator
from uwgen.emulator.from_manifest import with_mac
from uwgen.runtime.link.channels import DROP_REASONS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from commands_bench import Side, fibonacci  # noqa: E402 - one ROS side and the Fibonacci reference, as there

BITRATE = 4800.0
MRL = 64
HEADER = 4                   # bytes DESERT adds to each packet on the air
RADIUS = 100.0               # m: vehicles around the surface
SOUND = 1500.0
CALL_TIMEOUT = 30.0
RESULT_TIMEOUT = 60.0

MANIFEST = """\
network: fleetbench
package: {package}
sides:
  surface: {{port: 4000, link: {{max_read_length: {mrl}, period: {period}}}}}
mac: {mac}
fleet:
  vehicles: {vehicles}
  name: auv{{n}}
  port: 4001
  link: {{max_read_length: {mrl}, period: {period}}}
  id_stride: 4
  topics:
    - {{name: cmd, id: 10, type: std_msgs/msg/String, publisher: surface, queue: fifo, depth: 4, ttl: 60}}
    - {{name: telemetry, id: 11, type: std_msgs/msg/String, publisher: fleet, queue: fifo, depth: 4, ttl: 60}}
  services:
    - {{name: echo, id: 12, type: test_msgs/srv/BasicTypes, server: fleet, timeout: {timeout},
       request_fields: {omit}, response_fields: {omit}}}
  actions:
    - {{name: fib, id: 13, type: test_msgs/action/Fibonacci, server: fleet, accept_timeout: {timeout},
       result_timeout: {result}, max_goals: 2, feedback: false}}
"""


PERIOD = 0.2
SLOT_PACKETS = 3


# Only int32_value is used: the other 13 fields of BasicTypes are not sent (as a manifest
# would for a command), so a request is a few bytes, not 40.
OMIT = "{" + ", ".join(f"{f}: {{omit: true}}" for f in (
    "bool_value", "byte_value", "char_value", "float32_value", "float64_value", "int8_value",
    "uint8_value", "int16_value", "uint16_value", "uint32_value", "int64_value", "uint64_value",
    "string_value")) + "}"


def mac_section(mode: str, nodes: int, surface_weight: int = 1, surface_packets: int = 3) -> str:
    """The manifest's mac: for `nodes` sides. TDMA: a guard of one packet's air time plus the
    longest delay (across the circle), and a frame of `nodes` slots in each of which
    SLOT_PACKETS packets start a period apart; with `surface_weight` the same frame is shared
    by weight, the surface's slot that many times a vehicle's (a vehicle's ON window still
    starts SLOT_PACKETS packets back to back, as DESERT sends what waits in its queue;
    max_packet_per_slot and queue_size follow the surface's). Turns: `surface_packets` a
    surface turn."""
    common = f"bitrate: {BITRATE:g}, range: {2 * RADIUS:g}"
    if mode == "tdma":
        air = (MRL + HEADER) * 8 / BITRATE
        guard = round(air + 2 * RADIUS / SOUND + 0.02, 3)
        slot = guard + (SLOT_PACKETS - 1) * max(air, PERIOD) + 0.02
        frame = nodes * slot
        if surface_weight != 1 and frame / (nodes - 1 + surface_weight) - guard \
                < (SLOT_PACKETS - 1) * air + 0.01:
            frame = (nodes - 1 + surface_weight) * (guard + (SLOT_PACKETS - 1) * air + 0.01)
        weights = f", weights: {{surface: {surface_weight}}}" if surface_weight != 1 else ""
        return (f"{{mode: tdma, frame: {frame:.3f}, guard: {guard}, "
                f"max_packet_per_slot: {SLOT_PACKETS * surface_weight}, queue_size: "
                f"{max(10, SLOT_PACKETS * surface_weight)}{weights}, {common}}}")
    if mode == "turns":
        return f"{{mode: turns, leader: surface, packets: {{surface: {surface_packets}}}, {common}}}"
    return f"{{mode: none, {common}}}"


def build_package(vehicles: int, period: float, mac: str):
    from uwgen.cli import main as uwgen_main
    package = f"uwgen_fleetbench{vehicles}"
    root = Path(tempfile.mkdtemp(prefix=f"{package}_"))
    (root / "uwgen.yaml").write_text(MANIFEST.format(
        package=package, vehicles=vehicles, mrl=MRL, period=round(period, 3), mac=mac,
        timeout=CALL_TIMEOUT, result=RESULT_TIMEOUT, omit=OMIT))
    if uwgen_main(["--quiet", "build", "-m", str(root / "uwgen.yaml"),
                   "-o", str(root / "generated" / package)]) != 0:
        sys.exit("uwgen build of the benchmark manifest failed")
    return import_package(package, root / "generated")


def wait(future, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.05)
    return future.done()


def run(vehicles: int, args, base_domain: int) -> dict:
    names = [f"auv{n}" for n in range(1, vehicles + 1)]
    period = PERIOD
    package = build_package(vehicles, period, mac_section(
        args.mac, vehicles + 1, args.surface_weight if vehicles > 1 else 1,
        args.surface_packets if vehicles > 1 else 3))
    mac = package.MANIFEST.mac
    nodes = [NodeSpec("surface", dest=BROADCAST if vehicles > 1 else "auv1")]
    for k, name in enumerate(names):
        angle = 2 * math.pi * k / vehicles
        nodes.append(NodeSpec(name, position=(RADIUS * math.cos(angle), RADIUS * math.sin(angle), 0.0),
                              dest="surface"))
    scen = with_mac(Scenario(nodes=nodes, period=period, max_read_length=MRL, bitrate=BITRATE,
                             per=args.per, seed=args.seed), mac)
    frame = mac.frame if mac is not None and mac.mode == "tdma" else 2.0
    got = {"cmd": {v: set() for v in names}, "telemetry": {v: set() for v in names}}
    published = {"cmd": dict.fromkeys(names, 0), "telemetry": dict.fromkeys(names, 0)}
    ok = {"calls": 0, "goals": 0}
    lock = threading.Lock()
    sides: dict[str, Side] = {}
    bridges: dict[str, BridgeNode] = {}
    link_stats: dict[str, dict] = {}
    with run_emulator(scen) as emu:
        try:
            for i, name in enumerate(["surface", *names]):
                side = sides[name] = Side(name, base_domain + i)
                plan = BridgePlan.from_package(package, name)
                bridge = BridgeNode(plan, plan.options(port=emu.port(name), status_period=0),
                                    context=side.context, rng=random.Random(args.seed + i))
                side.spin_alone(bridge)
                bridges[name] = bridge
            surface = sides["surface"].node
            pubs, clients, actions = {}, {}, {}
            for v in names:
                vnode = sides[v].node

                def serve(req, resp):
                    resp.int32_value = req.int32_value * 3
                    return resp
                vnode.create_service(BasicTypes, f"/{v}/echo", serve)

                def execute(goal_handle):
                    goal_handle.succeed()
                    return Fibonacci.Result(sequence=fibonacci(goal_handle.request.order))
                ActionServer(vnode, Fibonacci, f"/{v}/fib", execute)
                vnode.create_subscription(String, f"/{v}/cmd",
                                          lambda m, v=v: got["cmd"][v].add(m.data), 10)
                surface.create_subscription(String, f"/{v}/telemetry",
                                            lambda m, v=v: got["telemetry"][v].add(m.data), 10)
                pubs[v] = (surface.create_publisher(String, f"/{v}/cmd", 10),
                           vnode.create_publisher(String, f"/{v}/telemetry", 10))
                clients[v] = surface.create_client(BasicTypes, f"/{v}/echo")
                actions[v] = ActionClient(surface, Fibonacci, f"/{v}/fib")
            for v in names:
                clients[v].wait_for_service(timeout_sec=20.0)
                actions[v].wait_for_server(timeout_sec=20.0)
            time.sleep(2 * frame + 2.0)   # links up, schemas exchanged
            stop = threading.Event()

            def chatter(v: str, offset: float):
                k = 0
                stop.wait(offset)
                while not stop.is_set():
                    k += 1
                    topics = ("telemetry", "cmd") if k % args.cmd_every == 0 else ("telemetry",)
                    for topic in topics:
                        pubs[v][topic == "telemetry"].publish(String(data=f"{v} {topic} {k}"))
                        with lock:
                            published[topic][v] += 1
                    stop.wait(args.every)

            def commands(v: str, n: int):
                calls = goals = 0
                for i in range(max(args.calls, args.goals)):
                    if i < args.calls:
                        value = 1000 * n + i
                        future = clients[v].call_async(BasicTypes.Request(int32_value=value))
                        if wait(future, CALL_TIMEOUT + 2) and future.result() is not None \
                                and future.result().int32_value == 3 * value:
                            calls += 1
                        elif not future.done():
                            clients[v].remove_pending_request(future)
                    if i < args.goals:
                        order = 3 + i % 20
                        sent = actions[v].send_goal_async(Fibonacci.Goal(order=order))
                        if wait(sent, CALL_TIMEOUT + 2) and sent.result().accepted:
                            result = sent.result().get_result_async()
                            if wait(result, RESULT_TIMEOUT + 2) and result.result().status == 4 \
                                    and list(result.result().result.sequence) == fibonacci(order):
                                goals += 1
                with lock:
                    ok["calls"] += calls
                    ok["goals"] += goals

            started = time.monotonic()
            talk = [threading.Thread(target=chatter, args=(v, k * args.every / vehicles), daemon=True)
                    for k, v in enumerate(names)]
            work = [threading.Thread(target=commands, args=(v, n), daemon=True)
                    for n, v in enumerate(names, 1)]
            for t in (*talk, *work):
                t.start()
            for t in work:
                t.join()
            stop.set()
            for t in talk:
                t.join()
            time.sleep(2 * frame + 3.0)   # what is in flight lands
            elapsed = time.monotonic() - started
        finally:
            counters = emu.all_counters()
            for name in bridges:          # every side's: a vehicle behind the goal is shown
                link_stats[name] = bridges[name].link.stats()
                link_stats[name]["services"] = {
                    k: getattr(c, "__dict__", c) for k, c in bridges[name].service_counters.items()}
            for side in sides.values():
                side.close()

    def ratio(topic):
        sent = sum(published[topic].values())
        return sum(len(s) for s in got[topic].values()) / sent if sent else float("nan")
    return {
        "network": f"surface + {vehicles} vehicle{'s' if vehicles > 1 else ''}",
        "telemetry": ratio("telemetry"), "cmd": ratio("cmd"),
        "per_vehicle": {v: len(got["telemetry"][v]) / max(1, published["telemetry"][v]) for v in names},
        "calls": (ok["calls"], vehicles * args.calls), "goals": (ok["goals"], vehicles * args.goals),
        "collision": sum(c["lost_collision"] for c in counters.values()),
        "per_lost": sum(c["lost_per"] for c in counters.values()),
        "sent": sum(c["packets_sent"] for c in counters.values()),
        "queue": max(c["max_queue_bytes"] for c in counters.values()),
        "mac_queue": max(c.get("max_mac_queue", 0) for c in counters.values()),
        "transit": "/".join(str(max(c.get(f"transit_{q}_ms", 0) for c in counters.values()))
                            for q in ("p50", "p95")),
        "time": elapsed, "mac": mac, "period": period, "links": link_stats, "emulator": counters,
    }


def behind(vehicle: str, row: dict) -> str:
    """One line on a vehicle whose telemetry fell behind the goal: its MAC timer's writes
    (timed, blind: with no frame phase known), its link's packets and channel drops, and
    what the emulator did with its packets."""
    st, emu = row["links"].get(vehicle, {}), row["emulator"].get(vehicle, {})
    mac = st.get("mac") or {}
    packets = st.get("packets") or {}
    channels = st.get("channels") or {}
    drops = {key: lost for key, ch in channels.items()
             if (lost := {k: ch[k] for k in DROP_REASONS if ch.get(k)})}
    picked = ("packets_sent", "lost_per", "lost_collision", "lost_no_client", "dropped_queue_full",
              "max_mac_queue", "transit_p95_ms", "transit_max_ms")
    return (f"mac {json_brief(mac)}; packets sent {packets.get('packets_sent')}, messages "
            f"{packets.get('messages_sent')}; channel drops {json_brief(drops)}; emulator "
            f"{json_brief({k: emu.get(k) for k in picked})}")


def json_brief(d: dict) -> str:
    return json.dumps(d, default=str, separators=(",", ":"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vehicles", type=int, default=8)
    ap.add_argument("--per", type=float, default=0.1)
    ap.add_argument("--calls", type=int, default=13, help="service calls per vehicle")
    ap.add_argument("--goals", type=int, default=13, help="action goals per vehicle")
    ap.add_argument("--every", type=float, default=8.0, help="seconds between a vehicle's telemetry messages")
    ap.add_argument("--cmd-every", type=int, default=3,
                    help="a command to each vehicle every this many telemetry messages")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--mac", choices=("tdma", "turns", "none"), default="tdma")
    ap.add_argument("--surface-weight", type=int, default=4,
                    help="tdma, fleet row: the surface's slot in vehicle slots (1: equal slots)")
    ap.add_argument("--surface-packets", type=int, default=6,
                    help="turns, fleet row: packets a surface turn")
    ap.add_argument("--verbose", action="store_true", help="also print link and emulator counters")
    args = ap.parse_args()
    base = int(os.environ.get("ROS_DOMAIN_ID") or 150)
    rows = [run(1, args, base), run(args.vehicles, args, base)]
    goal = 0.95 * (1 - args.per)
    print(f"\nfleet benchmark: PER {args.per:g}, {BITRATE:g} bit/s, {MRL} B packets, MAC {args.mac}, "
          f"seed {args.seed}; per vehicle 2 topics (telemetry every {args.every:g} s, a command every "
          f"{args.every * args.cmd_every:g} s), "
          f"{args.calls} calls, {args.goals} goals")
    head = (f"{'network':<22}{'telemetry':>10}{'commands':>10}{'calls ok':>14}{'goals ok':>14}"
            f"{'collided':>10}{'PER lost':>10}{'packets':>9}{'max queue B':>12}{'MAC queue':>10}"
            f"{'transit p50/p95 ms':>20}{'time s':>8}")
    print(head)
    for r in rows:
        calls = f"{r['calls'][0]}/{r['calls'][1]} {r['calls'][0] / max(1, r['calls'][1]):.2f}"
        goals = f"{r['goals'][0]}/{r['goals'][1]} {r['goals'][0] / max(1, r['goals'][1]):.2f}"
        print(f"{r['network']:<22}{r['telemetry']:>10.3f}{r['cmd']:>10.3f}{calls:>14}{goals:>14}"
              f"{r['collision']:>10}{r['per_lost']:>10}{r['sent']:>9}{r['queue']:>12}{r['mac_queue']:>10}"
              f"{r['transit']:>20}{r['time']:>8.0f}")
    fleet = rows[-1]
    print("  (first row: the two-side reference, same workload per vehicle, same run; "
          f"fleet's mac: {fleet['mac']})")
    print("  telemetry per vehicle: " + ", ".join(f"{v} {x:.2f}" for v, x in fleet["per_vehicle"].items()))
    met = (fleet["telemetry"] >= goal and fleet["calls"][0] >= 0.99 * fleet["calls"][1]
           and fleet["goals"][0] >= 0.99 * fleet["goals"][1])
    slow = [v for v, x in fleet["per_vehicle"].items() if x < goal]
    for v in slow:                    # what its MAC timer, its queues and the channel did
        print(f"  {v} behind the goal ({fleet['per_vehicle'][v]:.2f}): " + behind(v, fleet))
    if slow:                          # and what the surface refused (of all vehicles)
        refused = fleet["links"].get("surface", {}).get("reliability") or {}
        print("  the surface refused: " + json_brief(
            {k: refused.get(k) for k in ("stale", "clock_offset", "unexplained_delay", "unmeasured",
                                         "untimed", "bad_heads")}))
    if args.verbose:
        for r in rows:
            print(f"-- {r['network']}: emulator nodes", json.dumps(r["emulator"]))
            for name, st in r["links"].items():
                if name not in ("surface", "auv1"):
                    continue
                brief = {k: st.get(k) for k in ("mac", "packets", "reliability", "services")}
                print(f"-- {r['network']}: link of {name}", json.dumps(brief, default=str)[:3000])
    print(f"goal (telemetry >= {goal:.3f}, calls and goals >= 0.99): {'met' if met else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
