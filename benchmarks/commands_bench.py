#!/usr/bin/env python3
"""Commands benchmark (wire-format.md sections 5, 13, 15): service calls and action goals over the emulated acoustic
link at several packet error rates (plus the emulator's collisions), with two-way topic
traffic as in the demo, against the same workload without the commands' retries, same run.

    .venv/bin/python benchmarks/commands_bench.py [--per 0,0.1,0.2,0.3] [--calls 12]
                                                  [--goals 6] [--seed 3]

Per rate and mode it prints: calls and goals that succeeded within their timeouts with the
real result (the server's own response / Fibonacci sequence), duplicate executions at the
real server (a request or goal run more than once), and the air time spent on retries and
acknowledgements (copies of requests, goals, results and answers, the bridge's and the
link's copies in the same turn (uwgen.runtime.delivery.echoes); result acknowledgements and
requests; 4 bytes of framing each) as a share of all bytes the two sides wrote, and beside
it the floor: the least any repair could send for the same commands over a channel that
erases that share of packets (PER / (1 - PER) of the commands' first copies: a lower bound),
and the bytes of every report the two sides wrote (the A parts of wire-format 15.2: they
acknowledge topics' packets and commands' alike, and tell each command's fate, 15.6).
`--breakdown` also prints the retry and acknowledgement bytes by kind, each kind's own floor,
the fates the reports told (arrived, lost; copies spared, answers repaired), and each side's
packets the channel erased, with the floor at those rates (a run's channel erases more or
fewer than the nominal PER).

Modes: `retries` is this build; `reference` is the same build with the commands' retries off
(no request copies, no result copies, no result acknowledgements or requests; goals are
still sent again while unanswered, as wire format 1 always did).

The link is the demo's: 64 B every 0.2 s, 4800 bit/s, 1000 m (about 0.67 s each way).
The two sides use ROS_DOMAIN_ID and the next one: two benchmarks side by side need domains
two apart. A run whose bridges find another bridge in their ROS graph (the calls would go
round it, not over the link) stops with an error instead of counting them.

`--trace FILE` writes a JSON line per command payload offered, taken back and arriving, per
refusal of the receiving judge and per packet taken for writing (its number, its size, its
messages' heads and each message as the bridge offered it: air time, first or copy), and
the emulator's account of the channel (each packet it sent, each loss and its cause, as
`"ev": "emu"` lines: a collision beside the packets the bridges wrote);
`benchmarks/trace_commands.py FILE` prints, for each failed call or goal, what became of
its messages (each leg's copies, the packets that carried them, what arrived, refusals).

Reliable topics (wire format 2, docs/wire-format.md section 15) are measured first, on
simulated time, and `--ledger` runs the saturated one-way ledger: benchmarks/commands_sim.py.
"""
from __future__ import annotations

import argparse
import gc
import itertools
import json
import logging
import os
import random
import sys
import tempfile
import threading
import time
import traceback
from collections import Counter
from pathlib import Path

import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan, import_package
from uwgen.emulator import run_emulator
from uwgen.runtime.wire import envelope
from uwgen.runtime.wire.framing import OVERHEAD, ShortFrameDecoder

from commands_sim import MACS, ledger_table, scenario, topic_table  # the simulated half

MANIFEST = """\
network: cmdbench
package: uwgen_cmdbench
sides:
  surface: {port: 4000, link: {max_read_length: 64, period: 0.2}}
  vehicle: {port: 4001, link: {max_read_length: 64, period: 0.2}}
topics:
  - {name: /cmd, id: 4, type: std_msgs/msg/String, publisher: surface, queue: latest, rate: 2, ttl: 2}
  - {name: /pose, id: 5, type: std_msgs/msg/String, publisher: vehicle, queue: latest, rate: 1, ttl: 2}
services:
  - {name: /echo, id: 20, type: test_msgs/srv/BasicTypes, server: vehicle, timeout: 12}
actions:
  - {name: /fib, id: 9, type: test_msgs/action/Fibonacci, server: vehicle, accept_timeout: 12,
     result_timeout: 30, max_goals: 2, feedback: false}
"""
FIB_ID, ECHO_ID = 9, 20     # the manifest's /fib and /echo
COMMAND_IDS = (FIB_ID, ECHO_ID)
def build_package(mac: str = "none"):
    from uwgen.cli import main as uwgen_main
    root = Path(tempfile.mkdtemp(prefix="uwgen_cmdbench_"))
    name = f"uwgen_cmdbench_{mac}"
    (root / "uwgen.yaml").write_text(MANIFEST.replace("package: uwgen_cmdbench", f"package: {name}")
                                     + f"mac: {MACS[mac]}\n")
    if uwgen_main(["--quiet", "build", "-m", str(root / "uwgen.yaml"),
                   "-o", str(root / "generated" / name)]) != 0:
        sys.exit("uwgen build of the benchmark manifest failed")
    return import_package(name, root / "generated")


def fibonacci(n: int) -> list[int]:
    seq = [0, 1]
    while len(seq) < n + 1:
        seq.append(seq[-1] + seq[-2])
    return seq[:max(2, n + 1)]


class Side:
    """One ROS domain: the benchmark's node on an executor thread of its own, and each bridge
    added on another, as deployed (`uwgen bridge` spins its node alone on a single-threaded
    executor in its own process: uwgen.bridge.main). A MultiThreadedExecutor here spins hot
    while its pool runs a callback and starves the other threads of the interpreter's lock
    (a thread sleeping 10 ms in this process woke up to 0.4 s late): the link threads then
    missed their turns' bounds (wire-format.md section 16, REACT), figures of the bench's
    own making."""

    # two domains of the caller's (ROS_DOMAIN_ID and the next), reused run after run: a run's
    # contexts are shut down before the next starts
    _base = int(os.environ.get("ROS_DOMAIN_ID", "150"))
    domains = itertools.cycle((_base, _base + 1))

    def __init__(self, name: str, domain: int | None = None):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=next(Side.domains) if domain is None else domain,
                   signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        self.executors: list[SingleThreadedExecutor] = []
        self.node = rclpy.create_node(f"bench_{name}", context=self.context)
        self.spin_alone(self.node)

    def spin_alone(self, node) -> None:
        """Spin `node` (the bench's, or a bridge) on an executor and thread of its own."""
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(node)
        self.executors.append(executor)
        threading.Thread(target=self._spin, args=(executor,), daemon=True).start()

    def _spin(self, executor):
        try:
            executor.spin()
        except Exception:              # a bridge's callback failed: the run's figures are void
            try:
                alive = self.context.ok()
            except Exception:          # the context was destroyed under the spin: shutdown
                alive = False
            if alive:
                traceback.print_exc()

    def close(self):
        for executor in self.executors:
            for node in list(executor.get_nodes()):
                executor.remove_node(node)
                close = getattr(node, "close", None)
                try:
                    close() if close else node.destroy_node()
                except Exception:
                    pass
            executor.shutdown(timeout_sec=1.0)
        rclpy.shutdown(context=self.context)
        # the DDS participant goes only when the context is destroyed and nothing uses it
        # (action clients and servers hold their node until garbage collection): else the
        # next run, in the same domains, sees this run's bridges and its loop guard stops
        # bridging the services and actions they offer
        self.context.destroy()
        gc.collect()


def result_status(key: int, payload: bytes) -> bool:
    """A result's acknowledgement or request: /fib's kind-2 message whose third item is
    24 + handle (`18 xx`). A request of /echo whose seq is 24..255 opens the same way, and is
    a request."""
    return key == FIB_ID and payload[0] == 2 and len(payload) > 3 and payload[2] == 0x18


def channel_losses(counters: dict[str, dict[str, int]], sides=("surface", "vehicle")
                   ) -> dict[str, tuple[int, int]]:
    """Each side's packets the channel erased, as the emulator counts them: (lost to PER at
    the peer, sent) per side of a two-side run. The floor is figured at the nominal PER; a
    run's own channel erases more or fewer (at 20 %, one side's few hundred packets in a run
    lost 18-24 %), and this says how many."""
    first, second = sides
    peer = {first: second, second: first}
    return {side: (counters[peer[side]]["lost_per"], counters[side]["packets_sent"])
            for side in sides}


def floor_at(first: dict[str, int], losses: dict[str, tuple[int, int]]) -> float:
    """The floor's bytes at each side's own erasure rate (`channel_losses`): q / (1 - q) of
    the side's commands' first copies, summed."""
    total = 0.0
    for side, (lost, sent) in losses.items():
        q = lost / sent if sent else 0.0
        total += first.get(side, 0) * q / (1 - q) if q < 1 else 0.0
    return total


COPY_WINDOW = 60.0   # s: a payload offered again within this is a copy; later, a new message
                     # with equal bytes (a goal's answer, `3 9 handle 1`, recurs on every goal
                     # of a reused handle, minutes apart; copies go within a goal's life:
                     # result_timeout and 2 accept_timeouts, 54 s)


class Overhead:
    """Counts the bytes a bridge offers on command ids that are retries or acks (a copy taken
    back before it left, LinkScheduler.withdraw, is not counted)."""

    def __init__(self, bridge: BridgeNode, retries: bool):
        self.bytes = 0
        self.first = 0                        # bytes of commands' first copies (the floor)
        self.kinds: Counter = Counter()       # bytes by what they are (--breakdown)
        self.firsts: Counter = Counter()      # first copies' bytes by what they are
        # (key, payload) -> (when last offered, whether that was a copy)
        self.seen: dict[tuple[int, bytes], tuple[float, bool]] = {}
        send = bridge.wiring.send

        def kind(key: int, payload: bytes, status: bool) -> str:
            what = {(20, 2): "request copy", (20, 3): "response copy", (9, 2): "goal copy",
                    (9, 3): "goal answer copy" if len(payload) <= 5 else "result copy"
                    }.get((key, payload[0]), f"id {key} copy")
            return "result ack/query" if status else what

        def counted(key: int, payload: bytes, **kw) -> bool:
            if key in COMMAND_IDS:
                status = result_status(key, payload)
                if status and not retries:
                    return True                     # reference: no result status at all
                now = time.monotonic()
                copy = status or now - self.seen.get((key, payload), (-COPY_WINDOW, False))[0] < COPY_WINDOW
                if copy:
                    self.bytes += len(payload) + OVERHEAD
                    self.kinds[kind(key, payload, status)] += len(payload) + OVERHEAD
                else:
                    self.first += len(payload) + OVERHEAD
                    self.firsts[kind(key, payload, status)[:-len(" copy")]] += len(payload) + OVERHEAD
                self.seen[(key, payload)] = (now, copy)
            return send(key, payload, **kw)
        bridge.wiring.send = counted
        withdraw = bridge.wiring.withdraw

        def withdrawn(key: int, payload: bytes) -> bool:   # taken back before it left: no air time
            taken = withdraw(key, payload)
            if taken and key in COMMAND_IDS and self.seen.get((key, payload), (0, False))[1]:
                self.bytes -= len(payload) + OVERHEAD
                self.kinds[kind(key, payload, result_status(key, payload))] -= len(payload) + OVERHEAD
            return taken
        bridge.wiring.withdraw = withdrawn
        if not retries:
            bridge.standins.rtt.clear()                                  # no request copies
            bridge.action_servers._resend_results = lambda ident, now: None   # no result copies


TRACE = None     # --trace: a file of JSON lines, one per command payload, refusal and packet


def trace(side: str, bridge: BridgeNode) -> None:
    """Write down when each command payload was offered and arrived, each refusal of the
    receiving judge, and each packet taken for writing: where a failed call or goal lost its
    time (benchmarks/trace_commands.py reads it)."""
    out, lock = TRACE, threading.Lock()

    def put(**row):
        with lock:
            out.write(json.dumps({"t": round(time.monotonic(), 3), "side": side, **row}) + "\n")
    send, put_in = bridge.wiring.send, bridge.inbox.put

    def sending(key, payload, **kw):
        ok = send(key, payload, **kw)
        if key in COMMAND_IDS:
            put(ev="offer", key=key, p=payload[:12].hex(), ok=ok)
        return ok

    def arriving(payload):
        if len(payload) > 1 and payload[1] in COMMAND_IDS:
            put(ev="in", key=payload[1], p=bytes(payload)[:12].hex())
        return put_in(payload)
    bridge.wiring.send, bridge.inbox.put = sending, arriving
    if bridge.reliability is not None:
        judge = bridge.reliability.judge
        refuses = judge.refuses

        def refusing(ident, peer, time24, age):
            no = refuses(ident, peer, time24, age)
            if no:
                put(ev="refused", key=ident, age=round(age, 2), time=time24)
            return no
        judge.refuses = refusing
    take = bridge.link.connection.outbox.take

    def taking(now, pull, fit=None):
        batch = take(now, pull, fit)
        for frame in ShortFrameDecoder().feed(batch or b""):
            try:
                e = envelope.decode(frame)
            except Exception:
                continue
            put(ev="packet", no=e.number, ack=e.ack is not None, c=(e.control or b"").hex(),
                m=[envelope.to_v1(m)[:6].hex() for m in e.messages],
                bare=[bare(envelope.to_v1(m)) for m in e.messages], n=len(frame))
        return batch
    bridge.link.connection.outbox.take = taking

    def bare(v1: bytes) -> str:      # a message as the bridge offered it (its head taken off)
        try:
            return bytes(heads.take(v1).payload)[:12].hex()
        except Exception:
            return v1[:12].hex()
    heads = bridge.reliability.heads if bridge.reliability is not None else None
    withdraw = bridge.wiring.withdraw

    def withdrawing(key, payload):
        taken = withdraw(key, payload)
        if taken and key in COMMAND_IDS:
            put(ev="withdrawn", key=key, p=bytes(payload)[:12].hex())
        return taken
    bridge.wiring.withdraw = withdrawing


class ChannelTrace(logging.Handler):
    """The emulator's own account of the channel (each packet sent, each loss and its cause,
    at its DEBUG level) as trace lines, `"ev": "emu"`: a collision's time beside the packets
    the bridges wrote."""

    def emit(self, record: logging.LogRecord) -> None:     # Handler.handle holds its lock
        TRACE.write(json.dumps({"t": round(time.monotonic(), 3), "ev": "emu",
                                "msg": record.getMessage()}) + "\n")


def trace_channel() -> None:
    emulator = logging.getLogger("uwgen.emulator.core")
    emulator.setLevel(logging.DEBUG)
    emulator.propagate = False                 # its lines go to the trace, not the console
    emulator.addHandler(ChannelTrace(logging.DEBUG))


def run(package, per: float, seed: int, calls: int, goals: int, retries: bool,
        mac: str = "none") -> dict:
    scen = scenario(per, seed, mac)
    executed = {"calls": [], "goals": []}
    with run_emulator(scen) as emu:
        surface, vehicle = Side("surface"), Side("vehicle")
        try:
            bridges, overhead = {}, {}
            for name, side in (("surface", surface), ("vehicle", vehicle)):
                plan = BridgePlan.from_package(package, name)
                node = BridgeNode(plan, plan.options(port=emu.port(name), status_period=0),
                                  context=side.context, rng=random.Random(seed))
                side.spin_alone(node)
                bridges[name] = node
                overhead[name] = Overhead(node, retries)
                if TRACE is not None:
                    trace(name, node)

            def serve(req, resp):
                executed["calls"].append(req.int32_value)
                resp.int32_value = req.int32_value * 3
                return resp
            vehicle.node.create_service(BasicTypes, "/echo", serve)

            def execute(goal_handle):
                executed["goals"].append(goal_handle.request.order)
                goal_handle.succeed()
                return Fibonacci.Result(sequence=fibonacci(goal_handle.request.order))
            ActionServer(vehicle.node, Fibonacci, "/fib", execute)
            cmd = surface.node.create_publisher(String, "/cmd", 10)
            pose = vehicle.node.create_publisher(String, "/pose", 10)
            stop = threading.Event()

            def chatter():               # two-way traffic, as the demo's cmd_vel and pose
                k = 0
                while not stop.wait(0.5):
                    k += 1
                    cmd.publish(String(data=f"v={k % 7}.{k % 10} w=0.{k % 9}"))
                    if k % 2 == 0:
                        pose.publish(String(data=f"x={k % 11}.25 y={k % 13}.5 th=0.{k % 7}"))
            threading.Thread(target=chatter, daemon=True).start()

            client = surface.node.create_client(BasicTypes, "/echo")
            action = ActionClient(surface.node, Fibonacci, "/fib")
            client.wait_for_service(timeout_sec=10.0)
            action.wait_for_server(timeout_sec=10.0)
            time.sleep(3.0)                   # links up, graphs discovered (as the demo waits)
            shared = {n: dict(b.wiring.loops.hazards) for n, b in bridges.items() if b.wiring.loops.hazards}
            if shared:                        # calls would be served without the link
                stop.set()
                raise SystemExit(f"commands_bench: another uwgen bridge is in this run's ROS graph "
                                 f"({shared}): give each benchmark its own ROS_DOMAIN_ID, two apart "
                                 "(a run uses it and the next)")
            started = time.monotonic()
            ok_calls = ok_goals = 0
            for i in range(max(calls, goals)):
                if TRACE is not None:
                    TRACE.write(f'{{"t": {time.monotonic():.3f}, "ev": "round", "i": {i}}}\n')
                if i < calls:
                    future = client.call_async(BasicTypes.Request(int32_value=1000 + i))
                    deadline = time.monotonic() + 12.0
                    while not future.done() and time.monotonic() < deadline:
                        time.sleep(0.05)
                    if future.done() and future.result() is not None \
                            and future.result().int32_value == 3 * (1000 + i):
                        ok_calls += 1
                    else:
                        if TRACE is not None:
                            TRACE.write(f'{{"t": {time.monotonic():.3f}, "ev": "failed", "what": "call", "i": {i}}}\n')
                        client.remove_pending_request(future)
                if i < goals:
                    order = 3 + i % 20          # int32 sequence: fib(47) overflows
                    sent = action.send_goal_async(Fibonacci.Goal(order=order))
                    deadline = time.monotonic() + 12.0
                    while not sent.done() and time.monotonic() < deadline:
                        time.sleep(0.05)
                    if sent.done() and sent.result().accepted:
                        result = sent.result().get_result_async()
                        deadline = time.monotonic() + 31.0
                        while not result.done() and time.monotonic() < deadline:
                            time.sleep(0.05)
                        if result.done() and result.result().status == 4 \
                                and list(result.result().result.sequence) == fibonacci(order):
                            ok_goals += 1
                        elif TRACE is not None:
                            TRACE.write(f'{{"t": {time.monotonic():.3f}, "ev": "failed", "what": "result", "i": {i}}}\n')
                    elif TRACE is not None:
                        TRACE.write(f'{{"t": {time.monotonic():.3f}, "ev": "failed", "what": "goal", "i": {i}}}\n')
            elapsed = time.monotonic() - started
            stop.set()
            time.sleep(1.0)
            written = sum(b.link.stats()["connection"]["bytes_sent"] for b in bridges.values())
            extra = sum(o.bytes for o in overhead.values())
            first = sum(o.first for o in overhead.values())
            kinds = sum((o.kinds for o in overhead.values()), Counter())
            firsts = sum((o.firsts for o in overhead.values()), Counter())
            for name, b in bridges.items():    # the link's copies of commands in their own turn
                rel = b.link.stats().get("reliability", {})
                copies = rel.get("command_copies", {})
                for key, n in rel.get("command_copy_bytes", {}).items():
                    if int(key) in COMMAND_IDS:            # framing counted per copy, as above
                        extra += n + OVERHEAD * copies[key]
                        kinds[f"in-turn copy ({name})"] += n + OVERHEAD * copies[key]
            counters = emu.all_counters()
            collisions = sum(c["lost_collision"] for c in counters.values())
            losses = channel_losses(counters)
            floor_seen = floor_at({name: o.first for name, o in overhead.items()}, losses)
            # every A part written (reports on topics' and commands' packets alike: 15.2)
            reports = sum(b.link.stats().get("reliability", {}).get("report_bytes", 0)
                          for b in bridges.values())
            fates = sum((Counter(b.wiring.fates.stats()) for b in bridges.values()), Counter())
            if TRACE is not None:
                for name, b in bridges.items():
                    TRACE.write(json.dumps({"ev": "mac", "side": name, **b.link.stats()["mac"]}) + "\n")
        finally:
            surface.close()
            vehicle.close()
    # a duplicate run: the server ran a request or goal more often than the client sent it
    # (goal orders repeat every 20 goals, so runs are counted per order)
    sent_orders = Counter(3 + i % 20 for i in range(goals))
    dup = (len(executed["calls"]) - len(set(executed["calls"]))
           + sum(max(0, n - sent_orders[o]) for o, n in Counter(executed["goals"]).items()))
    capacity = 2 * elapsed / 0.2 * (64 + OVERHEAD)
    return {"calls": f"{ok_calls}/{calls}", "goals": f"{ok_goals}/{goals}", "dup": dup,
            "share": extra / written if written else 0.0, "capacity": extra / capacity,
            # the least any repair can send over a channel that erases a share `per` of the
            # packets: per / (1 - per) of the commands' bytes sent once (a lower bound: a
            # message cut across two packets is lost more often, and so are copies)
            "floor": first * per / (1 - per) / written if written and per < 1 else 0.0,
            "losses": losses, "floor_seen": floor_seen / written if written else 0.0,
            "time": elapsed, "collisions": collisions,
            "reports": reports / written if written else 0.0, "fates": dict(fates),
            "kinds": {k: v / written if written else 0.0 for k, v in sorted(kinds.items())},
            # each kind's own floor: what its first copies would need over that channel
            "floors": {k: v * per / (1 - per) / written if written and per < 1 else 0.0
                       for k, v in sorted(firsts.items())}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per", default="0,0.1,0.2,0.3")
    ap.add_argument("--calls", type=int, default=12)
    ap.add_argument("--goals", type=int, default=6)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--topics-only", action="store_true", help="only the reliable-topic table")
    ap.add_argument("--no-topics", action="store_true", help="skip the reliable-topic table")
    ap.add_argument("--no-reference", action="store_true",
                    help="commands: run this build only, not the reference without retries")
    ap.add_argument("--ledger", action="store_true",
                    help="only the saturated one-way ledger table (simulated), per --mac")
    ap.add_argument("--mac", default="none",
                    help="comma-separated MACs to run (none, tdma, turns; see MACS); the first "
                         "row of each rate is the reference")
    ap.add_argument("--breakdown", action="store_true",
                    help="after each row, the retry+ack bytes by what they are (share of bytes written)")
    ap.add_argument("--trace", help="write a JSON line per command payload, refusal and "
                                    "packet here, and the emulator's packets and losses "
                                    "(benchmarks/trace_commands.py reads it)")
    args = ap.parse_args()
    global TRACE
    if args.trace:
        TRACE = open(args.trace, "w", buffering=1)
        trace_channel()
    macs = args.mac.split(",")
    unknown = [m for m in macs if m not in MACS]
    if unknown:
        ap.error(f"--mac: unknown {', '.join(unknown)} (known: {', '.join(MACS)})")
    if args.ledger:
        ledger_table(macs)
        return 0
    if not args.no_topics:
        topic_table([float(p) for p in args.per.split(",")], args.seed, macs)
        print()
    if args.topics_only:
        return 0
    packages = {mac: build_package(mac) for mac in macs}
    print("| PER | mac | mode | calls ok | goals ok (real result) | duplicate runs | "
          "retry+ack bytes / bytes written | floor | / link capacity | reports / bytes written | "
          "collisions | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for per in (float(p) for p in args.per.split(",")):
        for mac in macs:
            for retries in (True,) if args.no_reference else (True, False):
                r = run(packages[mac], per, args.seed, args.calls, args.goals, retries, mac)
                print(f"| {per:.0%} | {mac} | {'retries' if retries else 'reference'} | "
                      f"{r['calls']} | {r['goals']} | {r['dup']} | {r['share']:.1%} | "
                      f"{r['floor']:.1%} | "
                      f"{r['capacity']:.1%} | {r['reports']:.1%} | {r['collisions']} | "
                      f"{r['time']:.0f} |", flush=True)
                if args.breakdown:
                    print("  retry+ack bytes: " + ", ".join(f"{k} {v:.1%}" for k, v in r["kinds"].items()))
                    print("  floor by kind: " + ", ".join(f"{k} {v:.1%}" for k, v in r["floors"].items()))
                    print("  command fates told: " + ", ".join(f"{k} {v}" for k, v in r["fates"].items()))
                    print("  channel: " + ", ".join(
                        f"{side}'s packets lost {lost / sent if sent else 0:.1%} ({lost} of {sent})"
                        for side, (lost, sent) in r["losses"].items())
                        + f"; floor at these rates {r['floor_seen']:.1%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
