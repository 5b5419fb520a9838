"""Real `uwgen bridge` processes over the emulator, for the delay series and the SIGKILL cases
of docs/seams.md section 8 (`benchmarks/truth_bench.py --processes`,
tests/e2e/test_truth_processes.py).

A `Network` builds a small manifest (one service, one action, served on the vehicle; sealed or
not), starts the emulator (`uwgen.emulator.server`, whose `hold` delays what the medium
delivers to a node: the request path holds what reaches the vehicle, the response path what
reaches the surface), runs each side's bridge as its own process (`python -m uwgen.cli
bridge`, ROS domains of its own) and, in this process, the real service and action server on
the vehicle's domain and the caller on the surface's. Every execution on the vehicle is
recorded with its time, so a cell can say what ran, when, and how often, beside what the
caller was told.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from uwgen import tether                                                  # noqa: E402
from uwgen.emulator import NodeSpec, Scenario, run_emulator               # noqa: E402

TIMEOUT, ACCEPT, RESULT = 4.0, 4.0, 30.0      # the service's timeout, the goal's deadlines
WINDOW = TIMEOUT + 1.0                         # a hold covers the call and all its retries
MANIFEST = """\
network: truthproc
package: {package}
{security}sides:
  surface: {{port: 4000, sender_id: 1, link: {{max_read_length: 64, period: 0.05}}}}
  vehicle: {{port: 4001, sender_id: 2, link: {{max_read_length: 64, period: 0.05}}}}
services:
  - {{name: /work, id: 20, type: test_msgs/srv/BasicTypes, server: vehicle, timeout: {timeout}}}
actions:
  - {{name: /fib, id: 9, type: test_msgs/action/Fibonacci, server: vehicle,
     accept_timeout: {accept}, result_timeout: {result}}}
"""
MIXED = """\
network: truthmixed
package: uwgen_truthmixed
sides:
  surface: {port: 4000, sender_id: 1, link: {max_read_length: 64, period: 0.05}}
  vehicle: {port: 4001, sender_id: 2, link: {max_read_length: 64, period: 0.05}}
topics:
  - {name: /chatter, id: 7, type: std_msgs/msg/String, publisher: vehicle, profile: rmw_desert}
services:
  - {name: /work, id: 20, type: test_msgs/srv/BasicTypes, server: vehicle, timeout: 4}
"""


def cli(*args: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "uwgen.cli", *args], capture_output=True,
                          text=True, env=env, timeout=timeout)


def child_env(domain: int | None = None) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    if domain is not None:
        env["ROS_DOMAIN_ID"] = str(domain)
    return env


def mixed_build(root: Path) -> tuple[int, str]:
    """`uwgen build` of a manifest with a native service beside an rmw_desert entry: the
    exit code and the error (the build refuses it, docs/seams.md section 8)."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "uwgen.yaml").write_text(MIXED)
    res = cli("build", "-m", str(root / "uwgen.yaml"), "-o", str(root / "generated" / "mixed"),
              env=child_env())
    return res.returncode, (res.stderr or res.stdout).strip().splitlines()[-1] if (
        res.stderr or res.stdout) else ""


class Ros:
    """One ROS domain in this process: a context, a node, an executor on a thread."""

    def __init__(self, domain: int, name: str):
        import rclpy
        from rclpy.executors import MultiThreadedExecutor
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2)
        self.node.destroy_node()
        self.context.try_shutdown()


@dataclass
class Vehicle:
    """The real servers on the vehicle's domain; each execution recorded as (id, time)."""

    ros: Ros
    goal_seconds: float = 1.0
    calls: list = field(default_factory=list)
    goals: list = field(default_factory=list)
    running: set = field(default_factory=set)

    def start(self) -> "Vehicle":
        from rclpy.action import ActionServer
        from rclpy.callback_groups import ReentrantCallbackGroup
        from test_msgs.action import Fibonacci
        from test_msgs.srv import BasicTypes
        group = ReentrantCallbackGroup()

        def serve(req, resp):
            self.calls.append((req.int32_value, time.monotonic()))
            resp.int32_value = req.int32_value
            return resp

        def execute(goal_handle):
            order = goal_handle.request.order
            self.goals.append((order, time.monotonic()))
            self.running.add(order)
            time.sleep(self.goal_seconds)
            self.running.discard(order)
            goal_handle.succeed()
            return Fibonacci.Result(sequence=[order])

        self.service = self.ros.node.create_service(BasicTypes, "/work", serve, callback_group=group)
        self.action = ActionServer(self.ros.node, Fibonacci, "/fib", execute, callback_group=group)
        return self

    def ran(self, ident: int, kind: str) -> list[float]:
        return [t for i, t in (self.calls if kind == "call" else self.goals) if i == ident]


class Network:
    """The emulator, both bridges as processes, the vehicle's servers and the surface's caller."""

    def __init__(self, root: Path, *, sealed: bool, domains: tuple[int, int],
                 goal_seconds: float = 1.0):
        self.root, self.sealed = root, sealed
        self.domains = dict(zip(("surface", "vehicle"), domains))
        self.goal_seconds = goal_seconds
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}

    # -- set-up and tear-down -----------------------------------------------------------

    def __enter__(self) -> "Network":
        self.root.mkdir(parents=True, exist_ok=True)
        package = "uwgen_truthproc_" + ("sealed" if self.sealed else "plain")
        security = "security: {mode: sign, key_file: net.key}\n" if self.sealed else ""
        self.manifest = self.root / "uwgen.yaml"
        self.manifest.write_text(MANIFEST.format(package=package, security=security,
                                                 timeout=TIMEOUT, accept=ACCEPT, result=RESULT))
        env = child_env()
        if self.sealed:
            res = cli("keygen", str(self.root / "net.key"), env=env)
            assert res.returncode == 0, res.stderr
        res = cli("build", "-m", str(self.manifest), "-o", str(self.root / "generated" / package),
                  env=env)
        assert res.returncode == 0, res.stdout + res.stderr
        scen = Scenario(nodes=[NodeSpec("surface", port=0, position=(0.0, 0.0, 0.0), dest="vehicle"),
                               NodeSpec("vehicle", port=0, position=(30.0, 0.0, 0.0), dest="surface")],
                        period=0.05, max_read_length=64, bitrate=48000.0, per=0.0, seed=5)
        self._emu_cm = run_emulator(scen)
        self.emu = self._emu_cm.__enter__()
        kind = "sealed" if self.sealed else "plain"       # one name per node of this process
        self.vehicle = Vehicle(Ros(self.domains["vehicle"], f"truth_vehicle_{kind}"),
                               self.goal_seconds).start()
        self.surface = Ros(self.domains["surface"], f"truth_caller_{kind}")
        from rclpy.action import ActionClient
        from test_msgs.action import Fibonacci
        from test_msgs.srv import BasicTypes
        self.client = self.surface.node.create_client(BasicTypes, "/work")
        self.goals = ActionClient(self.surface.node, Fibonacci, "/fib")
        for side in ("vehicle", "surface"):
            self.start_bridge(side)
        return self

    def __exit__(self, *exc) -> None:
        for side in list(self.procs):
            self.stop_bridge(side)
        self.surface.close()
        self.vehicle.ros.close()
        self._emu_cm.__exit__(None, None, None)

    def start_bridge(self, side: str) -> None:
        args = ["bridge", "-m", str(self.manifest), "--side", side, "--port",
                str(self.emu.port(side)), "--package-dir", str(self.root / "generated"),
                "--stats-file", str(self.root / f"{side}.json"), "--status-period", "1"]
        if self.sealed:
            args += ["--key-file", str(self.root / "net.key")]
        log = self.logs[side] = self.root / f"{side}.log"
        self.procs[side] = tether.popen([sys.executable, "-m", "uwgen.cli", *args],
                                        env=child_env(self.domains[side]),
                                        stdout=log.open("a"), stderr=subprocess.STDOUT)

    def kill_bridge(self, side: str) -> None:
        """SIGKILL: the bridge says nothing on the link, leaves its goals on the server."""
        proc = self.procs.pop(side)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)

    def stop_bridge(self, side: str) -> None:
        proc = self.procs.pop(side)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)

    def status(self, side: str) -> dict:
        try:
            return json.loads((self.root / f"{side}.json").read_text())
        except (OSError, ValueError):
            return {}

    def ready(self, timeout: float = 60.0) -> None:
        """Both bridges up and the link's clocks measured: a warm-up call succeeds."""
        deadline = time.monotonic() + timeout
        assert self.client.wait_for_service(timeout_sec=timeout), self.tail()
        assert self.goals.wait_for_server(timeout_sec=timeout), self.tail()
        while time.monotonic() < deadline:
            if self.call(-1, wait=TIMEOUT + 1.0)[0] == "response":
                return
        raise AssertionError("no warm-up call came through\n" + self.tail())

    def outcomes(self) -> dict:
        """What the surface's bridge learnt of its timed-out calls (docs/wire-format.md
        section 5.1): ran_after_timeout, not_run, outcome_unknown."""
        work = self.status("surface").get("services", {}).get("/work", {})
        return {k: work.get(k, 0) for k in ("ran_after_timeout", "not_run", "outcome_unknown")}

    def tail(self, lines: int = 15) -> str:
        out = []
        for side, log in self.logs.items():
            text = log.read_text() if log.exists() else ""
            out.append(f"--- {side}\n" + "\n".join(text.splitlines()[-lines:]))
        return "\n".join(out)

    # -- what the caller does -----------------------------------------------------------

    def call(self, ident: int, wait: float = TIMEOUT + 2.0) -> tuple[str, float]:
        """A service call; ('response' | 'no response', when it was made)."""
        from test_msgs.srv import BasicTypes
        made = time.monotonic()
        future = self.client.call_async(BasicTypes.Request(int32_value=ident))
        end = made + wait
        while not future.done() and time.monotonic() < end:
            time.sleep(0.02)
        if not future.done():
            self.client.remove_pending_request(future)
            return "no response", made
        return ("response" if future.result().int32_value == ident else "wrong response"), made

    def goal(self, order: int) -> "Goal":
        from test_msgs.action import Fibonacci
        return Goal(order, time.monotonic(), self.goals.send_goal_async(Fibonacci.Goal(order=order)))


@dataclass
class Goal:
    order: int
    made: float
    sent: object
    result: object = None

    def outcome(self, wait: float) -> str:
        """What the caller was told: rejected, succeeded, aborted, canceled, or waiting."""
        end = time.monotonic() + wait
        while not self.sent.done() and time.monotonic() < end:
            time.sleep(0.02)
        if not self.sent.done():
            return "no answer"
        handle = self.sent.result()
        if not handle.accepted:
            return "rejected"
        if self.result is None:
            self.result = handle.get_result_async()
        while not self.result.done() and time.monotonic() < end:
            time.sleep(0.02)
        if not self.result.done():
            return "no result"
        return {4: "succeeded", 5: "canceled", 6: "aborted"}.get(self.result.result().status,
                                                                  str(self.result.result().status))


@dataclass
class Cell:
    hold: float
    path: str
    call_told: str
    call_ran: list
    call_made: float
    goal_told: str
    goal_ran: list
    goal_made: float
    learnt: dict = field(default_factory=dict)   # what the calling bridge learnt afterwards

    def late(self) -> int:
        return (sum(1 for t in self.call_ran if t - self.call_made > TIMEOUT)
                + sum(1 for t in self.goal_ran if t - self.goal_made > ACCEPT))

    def double(self) -> int:
        return max(0, len(self.call_ran) - 1) + max(0, len(self.goal_ran) - 1)

    def matches(self) -> bool:
        """The caller's outcome is what the vehicle did: a response or a succeeded goal only
        when it ran once; 'no response' is what a timed-out call may say either way (the
        bridge learns and logs which, docs/wire-format.md section 5.1); a goal reported
        rejected or aborted never ran."""
        call_ok = (self.call_told == "response") == (len(self.call_ran) == 1) or \
            self.call_told == "no response"
        goal_ok = (self.goal_told == "succeeded") == (len(self.goal_ran) == 1)
        return call_ok and goal_ok


def delay_cell(net: Network, ident: int, hold: float, path: str, settle: float = 15.0) -> Cell:
    """A call and a goal made while what reaches the vehicle (request path) or the surface
    (response path) is held `hold` s: every delivery within WINDOW s, so nothing of them
    gets through in time. Waits until everything held was released and settled."""
    node = "vehicle" if path == "request" else "surface"
    before = net.outcomes()
    net.emu.hold(node, hold, window=WINDOW)
    goal = net.goal(ident)
    told, made = net.call(ident)
    goal_told = goal.outcome(wait=ACCEPT + RESULT + 10.0)
    left = made + WINDOW + hold + settle - time.monotonic()
    if left > 0:
        time.sleep(left)
    time.sleep(2.0)                                   # the status file's next write
    after = net.outcomes()
    return Cell(hold, path, told, net.vehicle.ran(ident, "call"), made, goal_told,
                net.vehicle.ran(ident, "goal"), goal.made,
                {k: after[k] - before.get(k, 0) for k in after if after[k] - before.get(k, 0)})


def kill_cell(net: Network, order: int, down: float) -> dict:
    """A goal running on the vehicle (goal_seconds long) when its bridge is SIGKILLed and
    started again `down` s later: what the caller is told, and whether anything was left
    running with nobody watching."""
    goal = net.goal(order)
    deadline = time.monotonic() + 20.0
    while order not in net.vehicle.running and time.monotonic() < deadline:
        time.sleep(0.02)
    running = order in net.vehicle.running
    net.kill_bridge("vehicle")
    time.sleep(down)
    net.start_bridge("vehicle")
    told = goal.outcome(wait=RESULT + 30.0)
    unsupervised = len(net.vehicle.running)
    return {"down": down, "running when killed": running, "told": told,
            "ran": len(net.vehicle.ran(order, "goal")), "left running": unsupervised}
