#!/usr/bin/env python3
"""Codec benchmark: uwgen's generated codecs against rclpy's C serializer, same run.

    .venv/bin/python benchmarks/codec_bench.py [--quick]

For realistic messages it prints bytes on the wire (uwgen native payload and frame vs
the CDR of rclpy's serialize_message) and microseconds per encode+decode (uwgen into
rclpy instances vs serialize_message + deserialize_message), the geometric mean of the
time ratios, and the time to build codecs for every installed interface. Below the table,
arrays of numeric structs (docs/wire-format.md section 4.2: by columns) the same way, outside
the geometric mean: a PolygonStamped of 50 points and a PoseArray of 20 poses.

uwgen and rclpy repetitions are interleaved (uwgen, rclpy, uwgen, rclpy, ...) and each
side keeps its best repetition, so a load that comes and goes on the machine weighs on
both sides alike instead of on whichever happened to run during it.
"""
from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
import timeit
from pathlib import Path

from builtin_interfaces.msg import Time
import random

from geometry_msgs.msg import Point32, PolygonStamped, Pose, PoseArray, PoseStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import BatteryState, Imu, LaserScan, NavSatFix, NavSatStatus
from std_msgs.msg import Header, String

from uwgen.codegen import generate
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD  # 0x99 0x99 LEN ... 0x55


def header(frame: str) -> Header:
    return Header(stamp=Time(sec=1763712000, nanosec=250_000_000), frame_id=frame)


def samples() -> dict[str, object]:
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.5, 0.3
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = 12.34, -5.6, -20.1
    pose.orientation.z, pose.orientation.w = 0.3826834, 0.9238795
    fix = NavSatFix(header=header("gps"), latitude=45.406435, longitude=11.876761, altitude=-3.2,
                    status=NavSatStatus(status=0, service=1), position_covariance_type=2)
    fix.position_covariance = [2.5, 0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0, 6.0]
    imu = Imu(header=header("imu"))
    imu.orientation.x, imu.orientation.w = 0.0123, 0.9999
    imu.angular_velocity.z = 0.021
    imu.linear_acceleration.x, imu.linear_acceleration.z = 0.12, 9.81
    imu.orientation_covariance = [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01]
    imu.angular_velocity_covariance = [0.001, 0, 0, 0, 0.001, 0, 0, 0, 0.001]
    imu.linear_acceleration_covariance = [0.1, 0, 0, 0, 0.1, 0, 0, 0, 0.1]
    odom = Odometry(header=header("odom"), child_frame_id="base_link")
    odom.pose.pose = pose
    odom.pose.covariance = [0.05 if i % 7 == 0 else 0.0 for i in range(36)]
    odom.twist.twist = twist
    odom.twist.covariance = [0.01 if i % 7 == 0 else 0.0 for i in range(36)]
    battery = BatteryState(header=header("battery"), voltage=15.8, temperature=21.5, current=-2.4,
                           charge=8.2, capacity=10.0, design_capacity=10.0, percentage=0.82,
                           power_supply_status=2, power_supply_health=1, power_supply_technology=3,
                           present=True, cell_voltage=[3.95, 3.96, 3.94, 3.95],
                           cell_temperature=[21.0, 21.5, 22.0, 21.5], location="hull", serial_number="AUV-7")
    stamped = PoseStamped(header=header("map"), pose=pose)
    scan = LaserScan(header=header("laser"), angle_min=-math.pi, angle_max=math.pi,
                     angle_increment=2 * math.pi / 360, time_increment=1e-4, scan_time=0.1,
                     range_min=0.1, range_max=30.0)
    scan.ranges = [0.5 + 20.0 * abs(math.sin(k * 0.05)) for k in range(360)]
    scan.intensities = [float(100 + k % 50) for k in range(360)]
    return {
        "geometry_msgs/msg/Twist": twist, "geometry_msgs/msg/Pose": pose,
        "geometry_msgs/msg/PoseStamped": stamped, "sensor_msgs/msg/LaserScan": scan,
        "sensor_msgs/msg/NavSatFix": fix, "sensor_msgs/msg/Imu": imu, "nav_msgs/msg/Odometry": odom,
        "sensor_msgs/msg/BatteryState": battery, "std_msgs/msg/String": String(data="surfacing in 5 min ok"[:20]),
    }


def struct_arrays() -> dict[str, object]:
    """Arrays of numeric structs, sent by columns (section 4.2)."""
    rnd = random.Random(5)
    poly = PolygonStamped(header=header("map"))
    poly.polygon.points = [Point32(x=rnd.uniform(-500, 500), y=rnd.uniform(-500, 500), z=0.0) for _ in range(50)]
    poses = PoseArray(header=header("map"))
    for _ in range(20):
        p = Pose()
        p.position.x, p.position.y, p.orientation.w = rnd.uniform(-100, 100), rnd.uniform(-100, 100), 1.0
        poses.poses.append(p)
    return {"geometry_msgs/msg/PolygonStamped": poly, "geometry_msgs/msg/PoseArray": poses}


# The realistic message types this benchmark times, in order: the geometric mean is taken over these.
TABLE = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/NavSatFix",
         "sensor_msgs/msg/Imu", "sensor_msgs/msg/BatteryState", "sensor_msgs/msg/LaserScan",
         "nav_msgs/msg/Odometry", "std_msgs/msg/String")


def per_call_us(fn, number: int) -> float:
    """Best of 5 repeats, in microseconds per call (the least disturbed measurement)."""
    return min(timeit.repeat(fn, number=number, repeat=5)) / number * 1e6


def interleaved_us(fns, number: int, repeat: int = 7) -> list[float]:
    """Best repetition of each of `fns` in microseconds per call, the repetitions of all
    of them interleaved (f0, f1, f0, f1, ...) so that they share the machine's load."""
    best = [math.inf] * len(fns)
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            best[k] = min(best[k], timeit.timeit(fn, number=number))
    return [b / number * 1e6 for b in best]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations")
    args = parser.parse_args()
    number = 200 if args.quick else 2000

    msgs = {name: samples()[name] for name in TABLE}
    extra = struct_arrays()
    with tempfile.TemporaryDirectory() as tmp:
        pkg = generate(Path(tmp), "uwgen_bench", names=[*msgs, *extra])
        rows, ratios = [], []
        for name, msg in {**msgs, **extra}.items():
            codec = pkg.codec(name)
            cls = type(msg)
            payload = codec.encode(msg, [0, 4])
            back, _ = codec.decode(payload, (0, 4))
            assert type(back) is cls
            cdr = serialize_message(msg)
            # (CDR bytes are not compared: rclpy leaves its padding bytes uninitialized)
            assert deserialize_message(serialize_message(back), cls) == deserialize_message(cdr, cls), \
                f"{name}: uwgen's round trip changed the message"

            def uwgen_round_trip(codec=codec, msg=msg):
                codec.decode(codec.encode(msg, [0, 4]), (0, 4))

            def rclpy_round_trip(msg=msg, cls=cls):
                deserialize_message(serialize_message(msg), cls)

            t_uw, t_ros = interleaved_us([uwgen_round_trip, rclpy_round_trip], number)
            if name in msgs:
                ratios.append(t_uw / t_ros)
            rows.append((name.split("/")[-1], len(payload), len(payload) + FRAME_OVERHEAD, len(cdr),
                         t_uw, t_ros, t_uw / t_ros))

        print(f"{'message':<14}{'payload B':>10}{'frame B':>9}{'CDR B':>7}{'uwgen us':>10}"
              f"{'rclpy us':>10}{'ratio':>7}")
        for name, pl, fr, cdr, tu, tr, ratio in rows[:len(msgs)]:
            print(f"{name:<14}{pl:>10}{fr:>9}{cdr:>7}{tu:>10.2f}{tr:>10.2f}{ratio:>7.2f}")
        geo = math.exp(statistics.fmean(math.log(r) for r in ratios))
        print(f"geometric mean of time ratios (uwgen / rclpy): {geo:.2f}  (goal: <= 0.5)")
        print("arrays of numeric structs, by columns (section 4.2; not in the mean):")
        for name, pl, fr, cdr, tu, tr, ratio in rows[len(msgs):]:
            print(f"{name:<14}{pl:>10}{fr:>9}{cdr:>7}{tu:>10.2f}{tr:>10.2f}{ratio:>7.2f}")
        total_frame = sum(r[2] for r in rows[:len(msgs)])
        total_cdr = sum(r[3] for r in rows[:len(msgs)])
        print(f"bytes: uwgen frames {total_frame} vs CDR {total_cdr} "
              f"({100 * (1 - total_frame / total_cdr):.0f}% smaller)")

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        everything = generate(Path(tmp), "uwgen_everything", all_installed=True)
        dt = time.perf_counter() - t0
        print(f"build codecs for every installed interface ({len(everything.CODECS)} types, native, "
              f"parse + generate + write + import): {dt:.2f} s  (goal: < 3 s)")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        both = generate(Path(tmp), "uwgen_everything2", all_installed=True, profiles=("native", "rmw_desert"))
        print(f"  ... both profiles ({len(both.CODECS)} codecs): {time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    main()
