"""A small vehicle simulator: turtlesim's kinematics, behind an acoustic link.

It integrates `geometry_msgs/Twist` commands on /turtle1/cmd_vel (unicycle model; a
command older than 1 s means stop, as turtlesim does) into a `turtlesim/msg/Pose` on
/turtle1/pose at 10 Hz, publishes a `sensor_msgs/BatteryState` at 1 Hz and log lines on
/vehicle/log (one of them longer than 255 bytes, so it crosses the link in fragments),
serves /turtle1/teleport_absolute and /vehicle/set_pen, and runs the mission action
/turtle1/rotate_absolute (turtlesim's RotateAbsolute: turn on the spot to a heading, with
the remaining angle as feedback).

    python -m uwgen.demo.vehicle [--record FILE] [--log-every 15]

The operator stamps each command with its sequence number in `linear.z` (which a 2-D
turtle ignores) so the report can measure command latency end to end.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

from uwgen.demo.records import Recorder, delivered_at, f32
from uwgen.demo.shutdown import init_ros, spin_until_stopped

CMD_TIMEOUT = 1.0        # s: a command this old means stop (turtlesim's rule)
STEP = 0.02              # s: integration step
POSE_PERIOD = 0.1        # s
BATTERY_PERIOD = 1.0     # s
MISSION_LINE_AT = 4.0    # s after start: the long log line (> 255 bytes: fragmented)
ROTATE_SPEED = 0.6       # rad/s at most while turning to a heading (the action)
ROTATE_TOLERANCE = 0.02  # rad: a heading this close is reached
ROTATE_STEP = 0.1        # s between rotation commands (and feedback)
LISTEN_WAIT = 10.0       # s at most to wait for the bridge's subscriptions before publishing


class VehicleSim:
    """The kinematics alone (no ROS), so it is testable with any clock."""

    def __init__(self, x: float = 5.5, y: float = 5.5, theta: float = 0.0):
        self.x, self.y, self.theta = x, y, theta
        self.lin = self.ang = 0.0
        self.cmd_time: float | None = None
        self.odometer = 0.0

    def command(self, lin: float, ang: float, now: float) -> None:
        self.lin, self.ang, self.cmd_time = lin, ang, now

    def step(self, now: float, dt: float) -> None:
        if self.cmd_time is None or now - self.cmd_time > CMD_TIMEOUT:
            self.lin = self.ang = 0.0
        self.theta = math.atan2(math.sin(self.theta + self.ang * dt),
                                math.cos(self.theta + self.ang * dt))
        self.x += self.lin * math.cos(self.theta) * dt
        self.y += self.lin * math.sin(self.theta) * dt
        self.odometer += abs(self.lin) * dt

    def teleport(self, x: float, y: float, theta: float) -> None:
        self.x, self.y, self.theta = x, y, theta
        self.lin = self.ang = 0.0


def turn_to(target: float, theta: float) -> float:
    """The signed angle (-pi..pi) from heading `theta` to heading `target`."""
    return math.atan2(math.sin(target - theta), math.cos(target - theta))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m uwgen.demo.vehicle", description=__doc__.split("\n")[0])
    parser.add_argument("--record", type=Path, help="write events as JSON lines here")
    parser.add_argument("--log-every", type=float, default=15.0, help="seconds between status log lines")
    parser.add_argument("--namespace", default="", help="the vehicle's namespace (a fleet's, e.g. /auv1)")
    parser.add_argument("--listen-wait", type=float, default=LISTEN_WAIT,
                        help="seconds at most to wait for the bridge's subscriptions before publishing")
    args, ros_args = parser.parse_known_args(argv)

    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.action import ActionServer, CancelResponse
    from rclpy.executors import ExternalShutdownException
    from rclpy.task import Future
    from sensor_msgs.msg import BatteryState
    from std_msgs.msg import String
    from turtlesim.action import RotateAbsolute
    from turtlesim.msg import Pose
    from turtlesim.srv import SetPen, TeleportAbsolute

    record = Recorder(args.record)
    stop = init_ros(["vehicle", *ros_args])   # a signal only stops the spinning (uwgen.demo.shutdown)
    node = rclpy.create_node("vehicle_sim")
    ns = args.namespace.rstrip("/")
    log = node.get_logger()
    sim = VehicleSim()
    start = time.monotonic()
    state = {"log_seq": 0, "battery": 1.0, "pen": None, "mission_sent": False, "last_log": start}

    pose_pub = node.create_publisher(Pose, f"{ns}/turtle1/pose", 10)
    battery_pub = node.create_publisher(BatteryState, f"{ns}/vehicle/battery", 10)
    log_pub = node.create_publisher(String, f"{ns}/vehicle/log", 10)

    def say(text: str) -> None:
        state["log_seq"] += 1
        seq = state["log_seq"]
        log_pub.publish(String(data=f"[{seq}] {text}"))
        record("log", seq=seq, size=len(text))
        log.info(f"log #{seq}: {text[:80]}{'...' if len(text) > 80 else ''}")

    def on_cmd(msg: Twist, info: Any) -> None:   # two parameters: rclpy passes MessageInfo
        now = time.monotonic()
        sim.command(msg.linear.x, msg.angular.z, now)
        record("cmd", at=delivered_at(info), k=int(msg.linear.z), lin=msg.linear.x, ang=msg.angular.z)

    def on_teleport(req, resp):
        sim.teleport(req.x, req.y, req.theta)
        record("teleport", x=req.x, y=req.y, theta=req.theta)
        say(f"teleported to x={req.x:.2f} y={req.y:.2f} theta={req.theta:.2f}")
        return resp

    def on_set_pen(req, resp):
        state["pen"] = (req.r, req.g, req.b, req.width, req.off)
        record("set_pen", r=req.r, g=req.g, b=req.b, width=req.width, off=req.off)
        say(f"pen {'off' if req.off else 'on'}: rgb({req.r},{req.g},{req.b}) width {req.width}")
        return resp

    def pause(seconds: float) -> Future:
        """A future done after `seconds`: the action waits without blocking the executor."""
        done = Future()

        def fire() -> None:
            timer.cancel()
            if not done.done():
                done.set_result(True)
        timer = node.create_timer(seconds, fire)
        return done

    async def rotate(goal_handle) -> RotateAbsolute.Result:
        target, start_theta = goal_handle.request.theta, sim.theta
        record("rotate_goal", theta=target)
        say(f"mission: turning to heading {target:.2f} rad")
        feedback = RotateAbsolute.Feedback()
        while True:
            remaining = turn_to(target, sim.theta)
            if goal_handle.is_cancel_requested:
                sim.command(0.0, 0.0, time.monotonic())
                goal_handle.canceled()
                break
            if abs(remaining) < ROTATE_TOLERANCE:
                sim.command(0.0, 0.0, time.monotonic())
                goal_handle.succeed()
                break
            sim.command(0.0, max(-ROTATE_SPEED, min(ROTATE_SPEED, 2.0 * remaining)), time.monotonic())
            feedback.remaining = remaining
            goal_handle.publish_feedback(feedback)
            await pause(ROTATE_STEP)
        delta = turn_to(sim.theta, start_theta)
        record("rotate_done", status=goal_handle.status, delta=delta, theta=sim.theta)
        return RotateAbsolute.Result(delta=delta)

    def step() -> None:
        now = time.monotonic()
        sim.step(now, STEP)
        if not state["mission_sent"] and now - start > MISSION_LINE_AT:
            state["mission_sent"] = True
            say("mission plan: survey square 4 m x 4 m at 0.4 m/s, turns at 0.6 rad/s, pen on; "
                "abort if battery below 20 %; report pose at 2 Hz and battery every 5 s; "
                "log events; acoustic link 64 B every 0.2 s, 4800 bit/s; this line is long on "
                "purpose (over 255 bytes) so it crosses the link as fragments")
        if now - state["last_log"] > args.log_every:
            state["last_log"] = now
            say(f"status: odometer {sim.odometer:.2f} m, battery {state['battery'] * 100:.1f} %")

    def publish_pose() -> None:
        p = Pose(x=sim.x, y=sim.y, theta=sim.theta, linear_velocity=sim.lin,
                 angular_velocity=sim.ang)
        pose_pub.publish(p)
        record("pose", x=f32(p.x), y=f32(p.y), theta=f32(p.theta),
               v=f32(p.linear_velocity), w=f32(p.angular_velocity))

    def publish_battery() -> None:
        state["battery"] = max(0.0, state["battery"] - 0.0005 - 0.002 * abs(sim.lin))
        b = BatteryState()
        b.header.stamp = node.get_clock().now().to_msg()
        b.header.frame_id = "vehicle"
        b.voltage = 12.0 + 4.8 * state["battery"]
        b.percentage = state["battery"]
        b.current = -1.5 - 4.0 * abs(sim.lin)
        b.present = True
        b.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
        battery_pub.publish(b)
        record("battery", stamp=b.header.stamp.sec + b.header.stamp.nanosec * 1e-9,
               pct=b.percentage)

    node.create_subscription(Twist, f"{ns}/turtle1/cmd_vel", on_cmd, 10)
    node.create_service(TeleportAbsolute, f"{ns}/turtle1/teleport_absolute", on_teleport)
    node.create_service(SetPen, f"{ns}/vehicle/set_pen", on_set_pen)
    ActionServer(node, RotateAbsolute, f"{ns}/turtle1/rotate_absolute", rotate,
                 cancel_callback=lambda goal_handle: CancelResponse.ACCEPT)
    # Publish once the bridge listens (bounded): what is published before its subscription
    # matched reaches nobody, and the report's counts would start with a gap.
    deadline = time.monotonic() + args.listen_wait
    while (min(p.get_subscription_count() for p in (pose_pub, battery_pub, log_pub)) == 0
           and time.monotonic() < deadline and not stop.is_set()):
        rclpy.spin_once(node, timeout_sec=0.05)
    start = state["last_log"] = time.monotonic()
    node.create_timer(STEP, step)
    node.create_timer(POSE_PERIOD, publish_pose)
    node.create_timer(BATTERY_PERIOD, publish_battery)
    say("vehicle simulator up at x=5.50 y=5.50")
    try:
        spin_until_stopped(node, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # ros_ok: the signal left the ROS context valid until ROS was shut down here.
        record("end", odometer=sim.odometer, ros_ok=rclpy.ok())
        record.close()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
