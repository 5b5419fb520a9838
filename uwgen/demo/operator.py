"""The scripted surface operator: sets the pen, teleports the turtle, drives a square.

It publishes `geometry_msgs/Twist` on /turtle1/cmd_vel at 10 Hz (twice the rate the
manifest lets over the link, so the link policy has work to do), calls
/vehicle/set_pen and /turtle1/teleport_absolute through the bridge, sends the mission
action /turtle1/rotate_absolute (turn to face north) after the square, and listens to
/turtle1/pose, /vehicle/battery and /vehicle/log. It steers to the square's corners by
the poses it receives (a `Pilot`), as a person at the surface would: open-loop commands
alone drift, because every lost command shifts a turn. Each command carries its
sequence number in `linear.z` for the latency report. It exits when the script is done.

    python -m uwgen.demo.operator [--record FILE] [--side 3.0] [--speed 0.5] [--turn 0.6]
                                  [--namespace /auv1] [--start 8,2]

In a fleet (`uwgen demo --vehicles 3`) one operator drives each vehicle: `--namespace` puts
every name under the vehicle's namespace and `--start` moves its square.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

from uwgen.demo.records import Recorder, delivered_at, f32
from uwgen.demo.shutdown import init_ros, interrupt_on_signals

RATE = 10.0                  # Hz of cmd_vel
START = (2.0, 2.0, 0.0)      # where the square starts (teleport target)
CALL_TIMEOUT = 12.0          # s the operator waits for a bridged call (the manifest's 10 s + margin)
CALL_TRIES = 3               # a request or response lost on the link fails the call: try again
MISSION_HEADING = math.pi / 2   # rad: the mission action turns the vehicle to face north
GOAL_WAIT = 15.0             # s for the goal's answer (the manifest's accept_timeout + margin)
RESULT_WAIT = 65.0           # s for its result (the manifest's result_timeout + margin)
LEARN_DISTANCE = 0.3         # m commanded between two poses before they tell what acted (Pilot.observe)
LEARN_WEIGHT = 0.3           # how much one such pair of poses moves the learned share
MIN_SHARE = 0.3              # the least share learned (a vehicle that stopped is not driven blind)
BLIND_LAGS = 2               # a pose older than this many lags cannot confirm a waypoint reached
KEPT_LAGS = 5                # commands are kept this many lags (a pair of poses that far apart still tells)


def square_waypoints(start: tuple[float, float], side: float, laps: int = 1) -> list[tuple[float, float]]:
    """Corners of a counter-clockwise square from `start`, back to `start`."""
    x, y = start
    corners = [(x + side, y), (x + side, y + side), (x, y + side), (x, y)]
    return [c for _ in range(laps) for c in corners]


def _point(text: str) -> tuple[float, float]:
    x, _, y = text.partition(",")
    return float(x), float(y)


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _clamp(v: float, lim: float) -> float:
    return max(-lim, min(lim, v))


class Pilot:
    """Steers to waypoints with poses that arrive late, as a pilot on the surface would.

    A pose received over the link shows the vehicle as it was about one link delay ago,
    and a command sent now acts one link delay later. The pilot therefore predicts where
    the vehicle will be when its next command lands: the last pose, moved on by the
    commands it sent during the last `lag` seconds (which that pose cannot show yet).
    Pure logic with explicit times, so it is tested without ROS.
    """

    def __init__(self, waypoints: list[tuple[float, float]], speed: float = 0.4,
                 turn: float = 0.6, lag: float = 1.0, reach: float = 0.15, rate: float = RATE,
                 share: float = 1.0):
        self.waypoints = list(waypoints)
        self.speed, self.turn, self.lag, self.reach = speed, turn, lag, reach
        self.dt = 1.0 / rate
        # the share of the time a command sent acts on the vehicle: 1 when commands arrive
        # more often than the vehicle's command timeout; less when a MAC delivers them in
        # bursts (a TDMA frame or a round of turns apart) and the vehicle stops in between;
        # the start of what observe() learns from the poses
        self.share = share
        self.index = 0
        self.pose: tuple[float, float, float, float] | None = None   # x, y, theta, t received
        self.sent: list[tuple[float, float, float]] = []              # (t, lin, ang)

    @property
    def done(self) -> bool:
        return self.index >= len(self.waypoints)

    def observe(self, x: float, y: float, theta: float, t: float) -> None:
        """A pose received at t. It also tells how much of what was commanded acted: the
        distance between two poses against the commands sent over the same span (each
        pose shows the commands up to `lag` before it arrived). A link that loses commands
        or brings them in bursts, with the vehicle stopping in between (its command
        timeout), moves it less than commanded; the prediction then counts `share` of
        each command (learned, LEARN_WEIGHT a pose), not all of it, and does not turn
        short of the corners."""
        if self.pose is not None:
            px, py, _, pt = self.pose
            if t - pt <= (KEPT_LAGS - 1) * self.lag:   # older commands are no longer kept
                commanded = sum(abs(lin) * self.dt for ts, lin, _ in self.sent
                                if pt - self.lag < ts <= t - self.lag)
                if commanded >= LEARN_DISTANCE:
                    moved = math.hypot(x - px, y - py) / commanded
                    self.share = min(1.0, max(MIN_SHARE, (1 - LEARN_WEIGHT) * self.share
                                              + LEARN_WEIGHT * moved))
        self.pose = (x, y, theta, t)

    def estimate(self, t: float) -> tuple[float, float, float] | None:
        if self.pose is None:
            return None
        x, y, th, t_rx = self.pose
        since = t_rx - self.lag
        self.sent = [c for c in self.sent if c[0] > t - KEPT_LAGS * self.lag]
        for ts, lin, ang in self.sent:
            if ts > since:
                th += ang * self.dt * self.share
                x += lin * math.cos(th) * self.dt * self.share
                y += lin * math.sin(th) * self.dt * self.share
        return x, y, th

    def command(self, t: float) -> tuple[float, float] | None:
        """The command to send at time t: (lin, ang); None when the last waypoint is reached."""
        est = self.estimate(t)
        if est is None:
            return 0.0, 0.0
        x, y, th = est
        blind = t - self.pose[3] > BLIND_LAGS * self.lag
        while not self.done:
            tx, ty = self.waypoints[self.index]
            if math.hypot(tx - x, ty - y) > self.reach:
                break
            if blind:
                # reached by the prediction alone, on an old pose (poses lost, commands
                # perhaps too): hold until a pose says where the vehicle is, never turn
                # for the next waypoint on a guess
                self.sent.append((t, 0.0, 0.0))
                return 0.0, 0.0
            self.index += 1
        if self.done:
            return None
        tx, ty = self.waypoints[self.index]
        dist = math.hypot(tx - x, ty - y)
        err = _wrap(math.atan2(ty - y, tx - x) - th)
        if abs(err) > 0.15:                       # turn on the spot first
            lin, ang = 0.0, _clamp(1.5 * err, self.turn)
        else:                                     # then drive, correcting the heading
            lin, ang = min(self.speed, 1.0 * dist + 0.05), _clamp(1.5 * err, self.turn / 2)
        self.sent.append((t, lin, ang))
        return lin, ang


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m uwgen.demo.operator", description=__doc__.split("\n")[0])
    parser.add_argument("--record", type=Path, help="write events as JSON lines here")
    parser.add_argument("--square-size", dest="side", type=float, default=4.0,
                        help="square side in metres")
    parser.add_argument("--speed", type=float, default=0.4, help="m/s along the sides")
    parser.add_argument("--turn", type=float, default=0.6, help="rad/s in the corners")
    parser.add_argument("--laps", type=int, default=1)
    parser.add_argument("--max-drive", type=float, default=120.0,
                        help="seconds after which the square is abandoned")
    parser.add_argument("--service-wait", type=float, default=30.0,
                        help="seconds to wait for the bridged services to appear")
    parser.add_argument("--namespace", default="", help="the vehicle's namespace (a fleet's, e.g. /auv1)")
    parser.add_argument("--start", type=_point, default=START[:2], metavar="X,Y",
                        help=f"where the square starts (default {START[0]:g},{START[1]:g})")
    parser.add_argument("--call-timeout", type=float, default=CALL_TIMEOUT,
                        help="seconds to wait for each bridged call (the manifest's timeout + margin)")
    parser.add_argument("--lag", type=float, default=1.0,
                        help="seconds the pilot expects a pose and a command to take over the link")
    parser.add_argument("--share", type=float, default=1.0,
                        help="the share of the time a command acts on the vehicle (less than 1 when "
                             "commands arrive further apart than the vehicle's command timeout); "
                             "the start of what the pilot then learns from the poses it receives")
    args, ros_args = parser.parse_known_args(argv)

    import rclpy
    from geometry_msgs.msg import Twist
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.executors import ExternalShutdownException
    from sensor_msgs.msg import BatteryState
    from std_msgs.msg import String
    from turtlesim.action import RotateAbsolute
    from turtlesim.msg import Pose
    from turtlesim.srv import SetPen, TeleportAbsolute

    record = Recorder(args.record)
    interrupt_on_signals(init_ros(["operator", *ros_args]))   # uwgen.demo.shutdown
    node = rclpy.create_node("operator")
    log = node.get_logger()
    ns = args.namespace.rstrip("/")
    waypoints = square_waypoints(args.start, args.side, args.laps)
    pilot = Pilot(waypoints, speed=args.speed, turn=args.turn, lag=args.lag, share=args.share)
    cmd_pub = node.create_publisher(Twist, f"{ns}/turtle1/cmd_vel", 10)
    pen = node.create_client(SetPen, f"{ns}/vehicle/set_pen")
    teleport = node.create_client(TeleportAbsolute, f"{ns}/turtle1/teleport_absolute")
    rotate = ActionClient(node, RotateAbsolute, f"{ns}/turtle1/rotate_absolute")
    seen = {"pose": 0, "battery": 0, "log": 0}

    def on_pose(p: Pose, info: Any) -> None:     # two parameters: rclpy passes MessageInfo
        seen["pose"] += 1
        record("pose_rx", at=delivered_at(info), x=f32(p.x), y=f32(p.y), theta=f32(p.theta),
               v=f32(p.linear_velocity), w=f32(p.angular_velocity))
        pilot.observe(p.x, p.y, p.theta, time.monotonic())
        if seen["pose"] == 1:
            log.info(f"first pose from the vehicle: x={p.x:.2f} y={p.y:.2f}")

    def on_battery(b: BatteryState, info: Any) -> None:
        seen["battery"] += 1
        record("battery_rx", at=delivered_at(info), stamp=b.header.stamp.sec + b.header.stamp.nanosec * 1e-9,
               pct=b.percentage)

    def on_log(s: String, info: Any) -> None:
        seen["log"] += 1
        seq = int(s.data[1:s.data.index("]")]) if s.data.startswith("[") and "]" in s.data else -1
        record("log_rx", at=delivered_at(info), seq=seq, size=len(s.data))
        log.info(f"vehicle says ({len(s.data)} B): {s.data[:100]}{'...' if len(s.data) > 100 else ''}")

    node.create_subscription(Pose, f"{ns}/turtle1/pose", on_pose, 10)
    node.create_subscription(BatteryState, f"{ns}/vehicle/battery", on_battery, 10)
    node.create_subscription(String, f"{ns}/vehicle/log", on_log, 10)

    def spin_for(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def call(client, request, what: str) -> bool:
        for attempt in range(1, CALL_TRIES + 1):
            if call_once(client, request, what if attempt == 1 else f"{what}, try {attempt}",
                         last=attempt == CALL_TRIES):
                return True
        return False

    def call_once(client, request, what: str, last: bool) -> bool:
        t0 = time.time()
        future = client.call_async(request)
        deadline = time.monotonic() + args.call_timeout
        while not future.done() and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        rtt = time.time() - t0
        ok = future.done() and future.result() is not None
        if not ok:
            client.remove_pending_request(future)
        record("call", name=client.srv_name, ok=ok, rtt=rtt, t0=t0)
        if ok:
            log.info(f"{what}: done in {rtt:.2f} s")
        elif last:   # every try lost: the demo counts this call as failed
            log.error(f"{what}: no response within {args.call_timeout:.0f} s, the last of "
                      f"{CALL_TRIES} tries: the call failed")
        else:        # a request or its response lost on the link: expected now and then
            log.warning(f"{what}: no response within {args.call_timeout:.0f} s (lost on the link); "
                        "trying again")
        return ok

    def spin_until(done, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while not done() and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        return done()

    def mission(theta: float) -> None:
        """Send the mission action's goal and wait for its result, recording both."""
        name = f"{ns}/turtle1/rotate_absolute"
        feedback: list[float] = []
        t0 = time.time()
        sent = rotate.send_goal_async(RotateAbsolute.Goal(theta=theta),
                                      feedback_callback=lambda m: feedback.append(m.feedback.remaining))
        if not spin_until(sent.done, max(GOAL_WAIT, args.call_timeout)) or not sent.result().accepted:
            # The goal or its answer lost on the link (the bridge resends the goal and then
            # gives up), or the vehicle refused it: reported, not a failure of the demo.
            why = "rejected by the vehicle" if sent.done() else "no answer (lost on the link)"
            log.warning(f"{name}: goal (heading {theta:.2f} rad) not accepted: {why}")
            record("mission", name=name, ok=False, status="rejected" if sent.done() else "no answer",
                   feedback=0, rtt=time.time() - t0)
            return
        log.info(f"{name}: goal accepted in {time.time() - t0:.2f} s, turning to {theta:.2f} rad")
        done = sent.result().get_result_async()
        ok = spin_until(done.done, RESULT_WAIT)
        status = done.result().status if ok else GoalStatus.STATUS_UNKNOWN
        names = {GoalStatus.STATUS_SUCCEEDED: "succeeded", GoalStatus.STATUS_CANCELED: "canceled",
                 GoalStatus.STATUS_ABORTED: "aborted"}
        rtt = time.time() - t0
        succeeded = status == GoalStatus.STATUS_SUCCEEDED
        record("mission", name=name, ok=succeeded, status=names.get(status, "no result"),
               feedback=len(feedback), rtt=rtt, delta=done.result().result.delta if succeeded else None)
        line = (f"{name}: {names.get(status, 'no result')} after {rtt:.2f} s, {len(feedback)} "
                "feedback messages" + (f", turned {done.result().result.delta:.2f} rad" if succeeded else ""))
        if succeeded:           # one call site per severity (rclpy's logger insists)
            log.info(line)
        else:
            log.warning(line)

    def drive(lin: float, ang: float, k: int) -> None:
        msg = Twist()
        msg.linear.x, msg.angular.z, msg.linear.z = float(lin), float(ang), float(k)
        cmd_pub.publish(msg)
        record("cmd", k=k, lin=lin, ang=ang)

    try:
        log.info("waiting for the bridged services")
        end = time.monotonic() + args.service_wait
        while not (pen.service_is_ready() and teleport.service_is_ready()) and time.monotonic() < end:
            spin_for(0.1)
        spin_for(2.0)  # let the bridges connect and the first poses arrive
        call(pen, SetPen.Request(r=255, g=120, b=0, width=3, off=0), "set_pen (orange, on)")
        (x0, y0), th0 = args.start, START[2]
        call(teleport, TeleportAbsolute.Request(x=x0, y=y0, theta=th0),
             f"teleport_absolute to ({x0}, {y0})")
        record("start", x=x0, y=y0, theta=th0, waypoints=waypoints)
        spin_for(1.5)  # a pose from after the teleport
        log.info(f"driving a {args.side:g} m square ({len(waypoints)} waypoints) at up to "
                 f"{args.speed:g} m/s, commands at {RATE:g} Hz, steering by the reported pose")
        k, t_start, target = 0, time.monotonic(), -1
        while time.monotonic() - t_start < args.max_drive:
            cmd = pilot.command(time.monotonic())
            if cmd is None:
                break
            if pilot.index != target:
                target = pilot.index
                log.info(f"heading for waypoint {target + 1}/{len(waypoints)} {waypoints[target]}")
            k += 1
            drive(*cmd, k)
            next_t = t_start + k / RATE  # a fixed schedule: no drift from loop overhead
            while time.monotonic() < next_t:
                rclpy.spin_once(node, timeout_sec=max(0.0, next_t - time.monotonic()))
        if not pilot.done:
            log.error(f"gave up after {args.max_drive:g} s at waypoint {pilot.index + 1}")
        for _ in range(int(RATE)):        # stop, and say so for a second
            k += 1
            drive(0.0, 0.0, k)
            spin_for(1.0 / RATE)
        record("stop")
        mission(MISSION_HEADING)
        call(pen, SetPen.Request(r=0, g=0, b=0, width=1, off=1), "set_pen (off)")
        spin_for(3.0)                     # the last poses and log lines
        log.info(f"done: received {seen['pose']} poses, {seen['battery']} battery states, "
                 f"{seen['log']} log lines")
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        record("end")
        record.close()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
