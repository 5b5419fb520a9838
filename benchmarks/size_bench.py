#!/usr/bin/env python3
"""Size and speed of field encodings: uwgen against CDR and DCCL, same run.

    .venv/bin/python benchmarks/size_bench.py [--quick]

Table 1, bytes per message (payload: header items included, frame bytes excluded):
  CDR        rclpy serialize_message (AUVStatus has no ROS type: CDR computed from its layout)
  native     uwgen profile native, no field encodings
  native+enc profile native with the field encodings below (one CBOR unsigned per field)
  pk no enc  profile packed without field encodings (what the bit packing alone gives)
  packed     profile packed with the same encodings (one bit-packed byte string)
  DCCL       DCCL's size for the same bounds from DCCL's published default-codec formulas
             (libdccl codecs page, "Default formulas"): 1-byte id, then the head fields and
             the body fields, each part padded to whole bytes; a number takes
             ceil(log2((max-min)/step + 2)) bits, an enum of n values ceil(log2(n + 1)),
             a bool 2, a repeated field ceil(log2(max_repeat + 1)) + max_repeat * q,
             a static field 0. The time stamp is a head field.
  DCCL 4.2   measured with a real DCCL 4.2.0 build (its own `dccl --encode`, every field
             `required` as a ROS field is): 17 / 3 / 26 / 17 bytes, stated as constants here
  pk wf2     the packed message as wire format 2 carries it in an envelope (docs/wire-format.md
             section 14): its one-byte header H and the bit-packed bytes, no byte-string head
             (plus one length byte when another message follows it in the packet)
Goals: packed <= DCCL + 1 byte; native+enc <= 1.6 x DCCL; pk wf2 <= DCCL 4.2.

Table 2, microseconds per encode+decode (into rclpy objects) of the quantized (native+enc)
and packed codecs against rclpy's serialize_message + deserialize_message, with the
geometric mean of the ratios (goal <= 1.0).

Table 3, arrays of numeric structs (docs/wire-format.md section 4.2): a PolygonStamped of 50
points (x, y not halves; z 0, or not a half either) in profile native by columns, against
its CDR and against the items it took before columns (the header's items, the count, then
every point's three float32 items, measured in this run). Goal: columns <= CDR.
"""
from __future__ import annotations

import argparse
import math
import random
import statistics
import struct
import tempfile
import textwrap
from pathlib import Path

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point32, PolygonStamped, Twist
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import BatteryState, NavSatFix, NavSatStatus

from uwgen.codegen import generate
from uwgen.runtime.wire.codec import pack_items
from uwgen.runtime.wire.envelope import from_v1, strip_packed_head

from codec_bench import per_call_us   # the same timing rule as the codec table

HERE = Path(__file__).resolve().parent
STAMP = Time(sec=1795420000 + 3 * 3600 + 17, nanosec=0)


def bits(codes: int) -> int:
    """Bits for `codes` distinct values: ceil(log2(codes))."""
    return (codes - 1).bit_length()


def dccl_number(lo: float, hi: float, step: float) -> int:
    return bits(round((hi - lo) / step) + 2)


def dccl_enum(n: int) -> int:
    return bits(n + 1)


def dccl_repeated(max_repeat: int, q: int) -> int:
    return bits(max_repeat + 1) + max_repeat * q


DCCL_TIME = dccl_number(0, 86400, 1)     # seconds of the day at 1 s
DCCL_BOOL = 2


def dccl_bytes(head: list[int], body: list[int]) -> int:
    return 1 + math.ceil(sum(head) / 8) + math.ceil(sum(body) / 8)


# --- the four messages: encodings, samples, DCCL field sizes --------------------------

AUV_FIELDS = """
  stamp: {time: day, resolution: 1}
  x: {min: -10000, max: 10000, precision: 1}
  y: {min: -10000, max: 10000, precision: 1}
  speed: {min: 0, max: 20, precision: 1}
  heading: {min: 0, max: 360, precision: 1}
  depth: {min: 0, max: 6500, precision: 0}
  altitude: {min: 0, max: 500, precision: 1}
  pitch: {min: -1.57, max: 1.57, precision: 2}
  roll: {min: -1.57, max: 1.57, precision: 2}
  mission_state: {values: [0, 1, 2, 3]}
  depth_mode: {values: [0, 1, 2]}
"""
AUV_DCCL = ([DCCL_TIME], [dccl_number(-10000, 10000, 0.1)] * 2 + [
    dccl_number(0, 20, 0.1), dccl_number(0, 360, 0.1), dccl_number(0, 6500, 1), dccl_number(0, 500, 0.1),
    dccl_number(-1.57, 1.57, 0.01), dccl_number(-1.57, 1.57, 0.01), dccl_enum(4), dccl_enum(3)])

TWIST_FIELDS = """
  linear.x: {min: -2, max: 2, precision: 2}
  linear.y: {static: 0}
  linear.z: {static: 0}
  angular.x: {static: 0}
  angular.y: {static: 0}
  angular.z: {min: -3.2, max: 3.2, precision: 1}
"""
TWIST_DCCL = ([], [dccl_number(-2, 2, 0.01), dccl_number(-3.2, 3.2, 0.1)])

FIX_FIELDS = """
  header.stamp: {time: day, resolution: 1}
  header.frame_id: {static: gps}
  status.status: {values: [-1, 0, 1, 2]}
  status.service: {values: [1, 2, 4, 8]}
  latitude: {min: -90, max: 90, precision: 6}
  longitude: {min: -180, max: 180, precision: 6}
  altitude: {min: -500, max: 500, precision: 2}
  position_covariance[]: {min: 0, max: 100, precision: 1}
  position_covariance_type: {values: [0, 1, 2, 3]}
"""
FIX_DCCL = ([DCCL_TIME], [dccl_enum(4), dccl_enum(4), dccl_number(-90, 90, 1e-6), dccl_number(-180, 180, 1e-6),
                          dccl_number(-500, 500, 0.01), dccl_repeated(9, dccl_number(0, 100, 0.1)),
                          dccl_enum(4)])   # float64[9] as a repeated field, max_repeat 9 (DCCL has no fixed arrays)

BATTERY_FIELDS = """
  header.stamp: {time: day, resolution: 1}
  header.frame_id: {static: battery}
  voltage: {min: 0, max: 60, precision: 2}
  temperature: {min: -5, max: 60, precision: 1}
  current: {min: -100, max: 100, precision: 1}
  charge: {min: 0, max: 100, precision: 1}
  capacity: {omit: true}
  design_capacity: {static: 10.0}
  percentage: {min: 0, max: 1, precision: 2}
  power_supply_status: {values: [0, 1, 2, 3, 4]}
  power_supply_health: {values: [0, 1, 2, 3, 4, 5, 6, 7, 8]}
  power_supply_technology: {static: 3}
  cell_voltage: {max_count: 4}
  cell_voltage[]: {min: 0, max: 5, precision: 2}
  cell_temperature: {omit: true}
  location: {static: hull}
  serial_number: {omit: true}
"""
BATTERY_DCCL = ([DCCL_TIME], [dccl_number(0, 60, 0.01), dccl_number(-5, 60, 0.1), dccl_number(-100, 100, 0.1),
                              dccl_number(0, 100, 0.1), dccl_number(0, 1, 0.01), dccl_enum(5), dccl_enum(9),
                              DCCL_BOOL, dccl_repeated(4, dccl_number(0, 5, 0.01))])


def twist() -> Twist:
    t = Twist()
    t.linear.x, t.angular.z = 0.5, 0.3
    return t


def navsatfix() -> NavSatFix:
    fix = NavSatFix(latitude=45.406435, longitude=11.876761, altitude=-3.2,
                    status=NavSatStatus(status=0, service=1), position_covariance_type=2)
    fix.header.stamp, fix.header.frame_id = STAMP, "gps"
    fix.position_covariance = [2.5, 0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0, 6.0]
    return fix


def battery() -> BatteryState:
    b = BatteryState(voltage=15.8, temperature=21.5, current=-2.4, charge=8.2, capacity=10.0, design_capacity=10.0,
                     percentage=0.82, power_supply_status=2, power_supply_health=1, power_supply_technology=3,
                     present=True, cell_voltage=[3.95, 3.96, 3.94, 3.95], location="hull")
    b.header.stamp, b.header.frame_id = STAMP, "battery"
    return b


def polygon(z_halves: bool) -> PolygonStamped:
    """50 points of a survey area's outline, in metres: x and y not halves."""
    rnd = random.Random(7)
    msg = PolygonStamped()
    msg.header.stamp, msg.header.frame_id = STAMP, "map"
    msg.polygon.points = [Point32(x=rnd.uniform(-500, 500), y=rnd.uniform(-500, 500),
                                  z=0.0 if z_halves else rnd.uniform(-50, 0)) for _ in range(50)]
    return msg


def items_size(codec, msg: PolygonStamped) -> int:
    """The payload as items: the header's items (an empty polygon's payload but its count
    `00`), then the count and the 150 float32 items (the form before columns)."""
    empty = PolygonStamped(header=msg.header)
    values = [struct_f32(v) for p in msg.polygon.points for v in (p.x, p.y, p.z)]
    return len(codec.encode(empty)) - 1 + len(pack_items([len(msg.polygon.points), *values]))


def struct_f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def auv_status(pkg):
    cls = pkg.codec("auv_msgs/msg/AUVStatus").plain_class()
    return cls(stamp=pkg.codec("builtin_interfaces/msg/Time").plain_class()(sec=STAMP.sec, nanosec=0),
               x=1234.5, y=-876.3, speed=1.5, heading=87.2, depth=120.0, altitude=32.5, pitch=-0.05, roll=0.02,
               mission_state=2, depth_mode=0)


AUV_CDR = 4 + 8 + 8 + 8 + 6 * 4 + 2    # encapsulation, stamp, x, y, six float32, two uint8 (aligned)

REAL_DCCL = {"AUVStatus": 17, "Twist (2 axes)": 3, "NavSatFix": 26, "BatteryState": 17}  # DCCL 4.2.0

ROWS = [  # (label, type, fields, DCCL (head, body), sample)
    ("AUVStatus", "auv_msgs/msg/AUVStatus", AUV_FIELDS, AUV_DCCL, None),
    ("Twist (2 axes)", "geometry_msgs/msg/Twist", TWIST_FIELDS, TWIST_DCCL, twist),
    ("NavSatFix", "sensor_msgs/msg/NavSatFix", FIX_FIELDS, FIX_DCCL, navsatfix),
    ("BatteryState", "sensor_msgs/msg/BatteryState", BATTERY_FIELDS, BATTERY_DCCL, battery),
]


def manifest_text() -> str:
    lines = ["network: bench", "sides:", "  a: {port: 4000}", "  b: {port: 4001}", "topics:"]
    ident = 4
    for _label, type_name, fields, _dccl, _sample in ROWS:
        for profile, with_fields in (("native", False), ("native", True), ("packed", False), ("packed", True)):
            lines += [f"  - name: /t{ident}", f"    id: {ident}", f"    type: {type_name}", "    publisher: a",
                      f"    profile: {profile}"]
            if with_fields:
                lines.append("    fields:" + textwrap.indent(fields, "    ").rstrip())
            ident += 1
    lines += [f"  - name: /polygon", f"    id: {POLYGON_ID}", "    type: geometry_msgs/msg/PolygonStamped",
              "    publisher: a"]
    return "\n".join(lines) + "\n"


POLYGON_ID = 100


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer iterations")
    args = parser.parse_args()
    number = 2000 if args.quick else 20000

    with tempfile.TemporaryDirectory() as tmp:
        manifest = Path(tmp) / "uwgen.yaml"
        manifest.write_text(manifest_text())
        pkg = generate(Path(tmp), "uwgen_size_bench", folders=[HERE / "interfaces"], manifest=manifest)
        from uwgen.runtime.wire import bits as _bits
        _bits.WALL.now_ns = lambda: (STAMP.sec + 60) * 10 ** 9   # a receiver clock near the stamp

        size_rows, time_rows, ratios = [], [], []
        for k, (label, type_name, _fields, (head, body), sample) in enumerate(ROWS):
            native, quantized, packed_plain, packed = (pkg.TOPICS[4 + 4 * k + j] for j in range(4))
            msg = sample() if sample else auv_status(pkg)
            cdr = len(serialize_message(msg)) if sample else AUV_CDR
            sizes = [len(c.encode(msg)) for c in (native, quantized, packed_plain, packed)]
            for c in (quantized, packed):   # the sizes are of messages that decode
                c.decode(c.encode(msg), ros=sample is not None)
            dccl = dccl_bytes(head, body)
            wf2 = from_v1(strip_packed_head(packed.encode(msg))).size()
            size_rows.append((label, cdr, *sizes, dccl, REAL_DCCL[label], wf2))
            if sample is None:
                continue
            cls = type(msg)

            def ros(msg=msg, cls=cls):
                deserialize_message(serialize_message(msg), cls)

            t_ros = per_call_us(ros, number)
            times = []
            for c in (quantized, packed):
                def trip(c=c, msg=msg):
                    c.decode(c.encode(msg))
                t = per_call_us(trip, number)
                times.append(t)
                ratios.append(t / t_ros)
            time_rows.append((label, t_ros, *times))

        poly = pkg.TOPICS[POLYGON_ID]
        poly_rows = []
        for label, z_halves in (("z 0", True), ("z not halves", False)):
            msg = polygon(z_halves)
            payload = poly.encode(msg)
            assert poly.decode(payload) == deserialize_message(serialize_message(msg), PolygonStamped)
            t_cols = per_call_us(lambda msg=msg: poly.decode(poly.encode(msg)), number // 10)
            t_ros = per_call_us(lambda msg=msg: deserialize_message(serialize_message(msg), PolygonStamped),
                                number // 10)
            poly_rows.append((label, len(serialize_message(msg)), items_size(poly, msg), len(payload), t_ros, t_cols))

    print("Table 1: bytes per message (payload, header included)")
    print(f"{'message':<16}{'CDR':>6}{'native':>8}{'nat+enc':>9}{'pk no enc':>10}{'packed':>8}{'DCCL':>6}"
          f"{'packed-DCCL':>13}{'nat+enc/DCCL':>14}{'DCCL 4.2':>10}{'pk wf2':>8}{'wf2-4.2':>10}")
    for label, cdr, nat, q, pk0, pk, dccl, real, wf2 in size_rows:
        ok_pk = "ok" if pk <= dccl + 1 else "MISS"
        ok_q = "ok" if q <= 1.6 * dccl else "MISS"
        ok_wf2 = "ok" if wf2 <= real else "MISS"
        print(f"{label:<16}{cdr:>6}{nat:>8}{q:>9}{pk0:>10}{pk:>8}{dccl:>6}{pk - dccl:>+10} {ok_pk:<4}"
              f"{q / dccl:>9.2f} {ok_q}{real:>8}{wf2:>8}{wf2 - real:>+7} {ok_wf2}")
    print("goals: packed <= DCCL + 1 byte; native+enc <= 1.6 x DCCL; pk wf2 <= DCCL 4.2")
    print()
    print("Table 2: microseconds per encode+decode (into rclpy messages)")
    print(f"{'message':<16}{'rclpy CDR':>10}{'nat+enc':>9}{'ratio':>7}{'packed':>8}{'ratio':>7}")
    for label, t_ros, t_q, t_pk in time_rows:
        print(f"{label:<16}{t_ros:>10.2f}{t_q:>9.2f}{t_q / t_ros:>7.2f}{t_pk:>8.2f}{t_pk / t_ros:>7.2f}")
    geo = math.exp(statistics.fmean(math.log(r) for r in ratios))
    print(f"geometric mean of time ratios (uwgen / rclpy): {geo:.2f}  (goal: <= 1.0)")
    print()
    print("Table 3: PolygonStamped, 50 points: bytes (payload, header included) and us per encode+decode")
    print(f"{'points':<14}{'CDR':>6}{'items':>7}{'columns':>9}{'col-CDR':>9}{'rclpy us':>10}{'columns us':>12}")
    for label, cdr, items, cols, t_ros, t_cols in poly_rows:
        ok = "ok" if cols <= cdr else "MISS"
        print(f"{label:<14}{cdr:>6}{items:>7}{cols:>9}{cols - cdr:>+7} {ok:<4}{t_ros:>8.1f}{t_cols:>12.1f}")
    print("goal: columns <= CDR (items: the form before columns, section 4)")


if __name__ == "__main__":
    main()
