"""Field encodings from the manifest, in profiles native and packed, on real rclpy
messages: exact round trips at grid points, within half a step elsewhere, strict and
clamp out of range, static/omit/enum/time/bounds, and total decoders."""
from __future__ import annotations

import math
from pathlib import Path
import textwrap
from fractions import Fraction

import cbor2
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist
from hypothesis import given
from hypothesis import strategies as st
from sensor_msgs.msg import BatteryState, NavSatFix

from uwgen.codegen import generate
from uwgen.runtime.wire import bits
from uwgen.runtime.wire.codec import DecodeError, EncodeError

from .test_properties import SETTINGS

TWIST = """
      linear.x: {min: -2, max: 2, precision: 2}
      linear.y: {static: 0}
      linear.z: {static: 0}
      angular.x: {static: 0}
      angular.y: {static: 0}
      angular.z: {min: -3.2, max: 3.2, resolution: 0.1, out_of_range: clamp}"""
BATTERY = """
      header.stamp: {time: day, resolution: 0.5}
      header.frame_id: {static: battery}
      voltage: {min: 0, max: 60, resolution: 0.05}
      cell_voltage: {max_count: 8}
      cell_voltage[]: {min: 0, max: 5, precision: 2}
      power_supply_status: {values: [0, 1, 2, 4]}
      location: {max_length: 8}
      serial_number: {omit: true}"""
FIX = """
      header.stamp: {time: epoch, epoch: 1763712000, span: 86400000, resolution: 0.001}
      latitude: {min: -90, max: 90, precision: 6}
      longitude: {min: -180, max: 180, precision: 6}
      position_covariance: {static: [1, 0, 0, 0, 1, 0, 0, 0, 4]}"""
IDS = {("twist", "native"): 4, ("twist", "packed"): 5, ("battery", "native"): 6, ("battery", "packed"): 7,
       ("fix", "native"): 8, ("fix", "packed"): 9}
TYPES = {"twist": "geometry_msgs/msg/Twist", "battery": "sensor_msgs/msg/BatteryState",
         "fix": "sensor_msgs/msg/NavSatFix"}
FIELDS = {"twist": TWIST, "battery": BATTERY, "fix": FIX}
PROFILES = ("native", "packed")


def manifest_text() -> str:
    text = "network: enc\nsides:\n  a: {port: 4000}\n  b: {port: 4001}\ntopics:\n"
    for (what, profile), ident in IDS.items():
        text += (f"  - name: /{what}_{profile}\n    id: {ident}\n    type: {TYPES[what]}\n"
                 f"    publisher: a\n    profile: {profile}\n    fields:{textwrap.indent(FIELDS[what], '  ')}\n")
    return text


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    folder = tmp_path_factory.mktemp("enc")
    (folder / "uwgen.yaml").write_text(manifest_text())
    return generate(folder, "uwgen_field_encodings", manifest=folder / "uwgen.yaml")


def codec(pkg, what: str, profile: str):
    return pkg.TOPICS[IDS[(what, profile)]]


def grid(lo: str, step: str, k: int) -> float:
    return float(Fraction(lo) + k * Fraction(step))


@pytest.mark.parametrize("profile", PROFILES)
def test_decimal_grid_values_come_back_exactly(pkg, profile):
    t = Twist()
    t.linear.x, t.angular.z = 2.3 - 1.0, 2.3   # 1.2999999999999998 rounds to the 1.3 grid point
    back = codec(pkg, "twist", profile).decode(codec(pkg, "twist", profile).encode(t))
    assert back.linear.x == 1.3 and back.angular.z == 2.3


@pytest.mark.parametrize("profile", PROFILES)
def test_every_grid_point_round_trips_exactly(pkg, profile):
    c = codec(pkg, "twist", profile)

    @SETTINGS
    @given(st.integers(0, 400), st.integers(0, 64))
    def check(i, j):
        t = Twist()
        t.linear.x, t.angular.z = grid("-2", "0.01", i), grid("-3.2", "0.1", j)
        back = c.decode(c.encode(t))
        assert (back.linear.x, back.angular.z) == (t.linear.x, t.angular.z)

    check()


@pytest.mark.parametrize("profile", PROFILES)
def test_values_inside_the_range_come_back_within_half_a_step(pkg, profile):
    c = codec(pkg, "twist", profile)

    @SETTINGS
    @given(st.floats(-2, 2), st.floats(-3.2, 3.2))
    def check(x, z):
        t = Twist()
        t.linear.x, t.angular.z = x, z
        back = c.decode(c.encode(t))
        for sent, got, step in ((x, back.linear.x, Fraction(1, 100)), (z, back.angular.z, Fraction(1, 10))):
            assert abs(Fraction(got) - Fraction(sent)) <= step / 2 + Fraction(math.ulp(got)) / 2

    check()


@pytest.mark.parametrize("profile", PROFILES)
def test_strict_out_of_range_is_an_error_naming_the_field(pkg, profile):
    c = codec(pkg, "twist", profile)

    @SETTINGS
    @given(st.one_of(st.floats(2.006, 1e300), st.floats(-1e300, -2.006), st.just(math.inf), st.just(math.nan)))
    def check(x):
        t = Twist()
        t.linear.x = x
        with pytest.raises(EncodeError) as info:
            c.encode(t)
        assert info.value.path == "linear.x"

    check()


@pytest.mark.parametrize("profile", PROFILES)
def test_clamp_saturates_and_counts(pkg, profile):
    c = codec(pkg, "twist", profile)

    @SETTINGS
    @given(st.one_of(st.floats(3.3, 1e300), st.just(math.inf)), st.booleans())
    def check(z, negative):
        before = bits.CLAMPED["angular.z"]
        t = Twist()
        t.angular.z = -z if negative else z
        back = c.decode(c.encode(t))
        assert back.angular.z == (-3.2 if negative else 3.2)
        assert bits.CLAMPED["angular.z"] == before + 1

    check()


@pytest.mark.parametrize("profile", PROFILES)
def test_static_fields_are_not_sent_and_come_back_as_declared(pkg, profile):
    c = codec(pkg, "twist", profile)
    t = Twist()
    t.linear.y = t.angular.x = 7.0
    back = c.decode(c.encode(t))
    assert (back.linear.y, back.angular.x) == (0.0, 0.0)
    fix = NavSatFix()
    fix.header.stamp = Time(sec=1763712000)
    fix.position_covariance = [9.0] * 9
    back = codec(pkg, "fix", profile).decode(codec(pkg, "fix", profile).encode(fix))
    assert list(back.position_covariance) == [1, 0, 0, 0, 1, 0, 0, 0, 4]


def test_quantized_twist_is_smaller_than_native_and_packed_smaller_still(pkg):
    t = Twist()
    t.linear.x, t.angular.z = 0.5, 0.3
    native = codec(pkg, "twist", "native").encode(t)
    packed = codec(pkg, "twist", "packed").encode(t)
    assert native == bytes([0x00, 0x04, 0x18, 0xFA, 0x18, 0x23])  # 250 = (0.5+2)/0.01, 35 = (0.3+3.2)/0.1
    # 401 codes -> 9 bits, 65 codes -> 7 bits: 250 << 7 | 35 = 0x7D23
    assert packed == bytes([0x00, 0x05, 0x42, 0x7D, 0x23])


def battery(sec: int, nanosec: int = 0) -> BatteryState:
    b = BatteryState(voltage=15.8, cell_voltage=[3.95, 3.96, 0.0, 5.0], power_supply_status=4, location="hull",
                     serial_number="AUV-7", present=True)
    b.header.stamp = Time(sec=sec, nanosec=nanosec)
    return b


@pytest.fixture
def wall_clock():
    saved = bits.WALL.now_ns
    yield bits.WALL
    bits.WALL.now_ns = saved


@pytest.mark.parametrize("profile", PROFILES)
def test_time_of_day_comes_back_within_twelve_hours_of_the_receivers_clock(pkg, profile, wall_clock):
    c = codec(pkg, "battery", profile)
    sent_at = 1795420000

    # The receiver places the *rounded* instant: rounding (up to half a step, 0.25 s here) can
    # carry a time 12 h - 1 s away to exactly 12 h, which reads as 12 h behind (wire format
    # section 8). So the skews drawn stay a whole second inside the bound.
    @SETTINGS
    @given(st.integers(0, 999_999_999), st.integers(-(12 * 3600 - 2), 12 * 3600 - 2))
    def check(nanosec, skew):
        wall_clock.now_ns = lambda: (sent_at + skew) * 10 ** 9
        back = c.decode(c.encode(battery(sent_at, nanosec)))
        sent = sent_at * 10 ** 9 + nanosec
        got = back.header.stamp.sec * 10 ** 9 + back.header.stamp.nanosec
        assert got % (5 * 10 ** 8) == 0 and abs(got - sent) <= 250_000_000

    check()


@pytest.mark.parametrize("profile", PROFILES)
def test_battery_fields_round_trip_with_their_encodings(pkg, profile, wall_clock):
    wall_clock.now_ns = lambda: 1795420000 * 10 ** 9
    c = codec(pkg, "battery", profile)
    back = c.decode(c.encode(battery(1795420000, 500_000_000)))
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1795420000, 500_000_000)
    assert back.header.frame_id == "battery" and back.serial_number == "" and back.location == "hull"
    assert back.power_supply_status == 4 and back.present is True
    assert back.voltage == pytest.approx(15.8, abs=1e-6)
    assert [round(v, 2) for v in back.cell_voltage] == [3.95, 3.96, 0.0, 5.0]


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("change, path", [
    (lambda b: setattr(b, "power_supply_status", 3), "power_supply_status"),
    (lambda b: setattr(b, "cell_voltage", [3.0] * 9), "cell_voltage"),
    (lambda b: setattr(b, "cell_voltage", [3.0, 5.2]), "cell_voltage[1]"),
    (lambda b: setattr(b, "location", "engine room"), "location"),
    (lambda b: setattr(b, "voltage", 61.0), "voltage"),
])
def test_battery_values_outside_their_encoding_name_the_field(pkg, profile, change, path):
    b = battery(1795420000)
    change(b)
    with pytest.raises(EncodeError) as info:
        codec(pkg, "battery", profile).encode(b)
    assert info.value.path == path


@pytest.mark.parametrize("profile", PROFILES)
def test_time_since_epoch_round_trips_to_the_millisecond(pkg, profile):
    c = codec(pkg, "fix", profile)
    fix = NavSatFix(latitude=45.406435, longitude=11.876761, altitude=-3.2)
    fix.header.stamp = Time(sec=1763712000 + 86399, nanosec=123_456_789)
    back = c.decode(c.encode(fix))
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1763712000 + 86399, 123_000_000)
    assert (back.latitude, back.longitude) == (45.406435, 11.876761)
    fix.header.stamp = Time(sec=1763711999)
    with pytest.raises(EncodeError) as info:
        c.encode(fix)
    assert info.value.path == "header.stamp"


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("what", ["twist", "battery", "fix"])
def test_decoders_with_field_encodings_stay_total(pkg, profile, what):
    c = codec(pkg, what, profile)
    ident = IDS[(what, profile)]

    @SETTINGS
    @given(st.one_of(st.binary(max_size=120),
                     st.binary(max_size=40).map(lambda b: bytes([0, ident]) + b),
                     st.binary(max_size=40).map(lambda b: bytes([0, ident]) + cbor2.dumps(b)),
                     st.lists(st.integers(0, 2 ** 70), max_size=16).map(
                         lambda xs: bytes([0, ident]) + b"".join(cbor2.dumps(x) for x in xs))))
    def check(data):
        try:
            c.decode(data, ros=False)
        except DecodeError:
            pass

    check()


def test_native_index_out_of_range_is_a_decode_error_naming_the_field(pkg):
    c = codec(pkg, "twist", "native")
    with pytest.raises(DecodeError) as info:
        c.decode(bytes([0x00, 0x04, 0x19, 0x01, 0x92, 0x00]))   # 402 > 400
    assert info.value.path == "linear.x"


def exact_grid_value(x: float, lo: Fraction, step: Fraction) -> float:
    """What the wire must carry for x: the grid point round-half-up((x - lo) / step), exactly."""
    n = math.floor((Fraction(x) - lo) / step + Fraction(1, 2))
    return float(lo + n * step)


@pytest.mark.parametrize("profile", PROFILES)
def test_the_float_fast_path_rounds_exactly_like_the_fractions(pkg, profile):
    """Values at and next to the half-way points between grid points, where a float
    estimate alone would round the wrong way."""
    c = codec(pkg, "twist", profile)
    lo, step = Fraction(-2), Fraction(1, 100)

    @SETTINGS
    @given(st.integers(0, 399), st.integers(-3, 3))
    def check(k, ulps):
        x = float(lo + k * step + step / 2)
        for _ in range(abs(ulps)):
            x = math.nextafter(x, math.inf if ulps > 0 else -math.inf)
        t = Twist()
        t.linear.x = x
        assert c.decode(c.encode(t)).linear.x == exact_grid_value(x, lo, step)

    check()


def test_quantize_all_fast_and_exact_agree():
    lo, step = Fraction(-157, 100), Fraction(1, 100)
    values = [float(lo + k * step + step / 2) for k in range(314)] + [-1.57, 1.57, 0.0, 1e-17]
    fast = (float(lo), float(1 / step), 2.0 ** -30)
    assert bits.quantize_all(values, -157, 1, 100, 314, False, "p", fast) == \
        bits.quantize_all(values, -157, 1, 100, 314, False, "p")


SERVICES = """network: srv
sides:
  a: {port: 4000}
  b: {port: 4001}
topics:
  - name: /diag
    id: 4
    type: diagnostic_msgs/msg/DiagnosticArray
    publisher: a
    profile: PROFILE
    fields:
      header.stamp: {time: epoch, epoch: 1700000000, span: 100000000}
      header.frame_id: {omit: true}
services:
  - name: /set
    id: 20
    type: std_srvs/srv/SetBool
    server: b
    profile: PROFILE
    response_fields:
      message: {max_length: 12}
  - name: /teleport
    id: 21
    type: turtlesim/srv/TeleportAbsolute
    server: b
    profile: PROFILE
    request_fields:
      x: {min: 0, max: 12, precision: 2}
      y: {min: 0, max: 12, precision: 2}
      theta: {min: -3.142, max: 3.142, precision: 3}
"""


@pytest.fixture(scope="module", params=PROFILES)
def srv_pkg(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("srv")
    (folder / "uwgen.yaml").write_text(SERVICES.replace("PROFILE", request.param))
    root = Path(__file__).resolve().parents[2] / "msg_samples"
    return generate(folder, f"uwgen_srv_{request.param}", folders=[root], manifest=folder / "uwgen.yaml")


def test_request_and_response_fields_apply_to_their_own_part(srv_pkg):
    from std_srvs.srv import SetBool
    tp = srv_pkg.SERVICES[21]
    req = tp.request.plain_class()(x=5.555, y=1.0, theta=3.1)   # the float 5.555 is 5.55499999...: 5.55
    seq, back = tp.decode_request(tp.encode_request(7, req), ros=False)
    assert seq == 7 and (back.x, back.y, back.theta) == (5.55, 1.0, 3.1)
    s = srv_pkg.SERVICES[20]
    resp = SetBool.Response(success=True, message="done")
    assert s.decode_response(s.encode_response(3, resp))[1] == resp
    with pytest.raises(EncodeError) as info:
        s.encode_response(3, SetBool.Response(success=True, message="a much longer message"))
    assert info.value.path == "message"
    request = SetBool.Request(data=True)
    assert s.decode_request(s.encode_request(4, request))[1] == request


def test_encodings_on_a_type_with_arrays_of_messages(srv_pkg):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    msg = DiagnosticArray(status=[DiagnosticStatus(level=b"\x01", name="dvl", message="ok",
                                                   values=[KeyValue(key="beams", value="4")])])
    msg.header.stamp = Time(sec=1763712000, nanosec=0)
    msg.header.frame_id = "not sent"
    back = srv_pkg.TOPICS[4].decode(srv_pkg.TOPICS[4].encode(msg))
    assert back.status == msg.status and back.header.stamp == msg.header.stamp and back.header.frame_id == ""


def test_the_first_clamp_of_a_field_is_logged_once(caplog):
    bits.CLAMPED.pop("probe.x", None)
    with caplog.at_level("WARNING", logger="uwgen.codec"):
        for v in (7.0, 8.0, -9.0):
            bits.quantize(v, -32, 1, 10, 64, True, "probe.x")
    assert bits.CLAMPED["probe.x"] == 3
    assert [r.getMessage() for r in caplog.records].count(
        "probe.x: 7.0 is outside -3.2..3.2 and was clamped (out_of_range: clamp); later ones are only counted "
        "(uwgen.runtime.wire.bits.CLAMPED)") == 1 and len(caplog.records) == 1


def test_the_reference_manifest_builds_and_its_encodings_work(tmp_path):
    root = Path(__file__).resolve().parents[2] / "msg_samples"
    pkg = generate(tmp_path, "uwgen_reference_check", folders=[root], manifest=root / "manifest-reference.yaml")
    pen = pkg.SERVICES[21]
    req = pen.request.plain_class()(r=255, g=120, b=0, width=3, off=1)
    payload = pen.encode_request(5, req)
    assert payload == bytes([0x02, 0x15, 0x05, 0x18, 0xFF, 0x18, 0x78, 0x00, 0x03, 0x01])   # "off" 1 is index 1
    assert pen.decode_request(payload, ros=False) == (5, req)
    with pytest.raises(EncodeError) as info:
        pen.encode_request(5, pen.request.plain_class()(width=16))
    assert info.value.path == "width"


def fingerprint_of(tmp_path, name: str, fields: str) -> bytes:
    folder = tmp_path / name
    folder.mkdir()
    text = ("network: fp\nsides:\n  a: {port: 4000}\n  b: {port: 4001}\ntopics:\n"
            "  - name: /cmd_vel\n    id: 4\n    type: geometry_msgs/msg/Twist\n    publisher: a\n"
            "    profile: packed\n    fields:\n" + textwrap.indent(textwrap.dedent(fields).strip(), "      ") + "\n")
    (folder / "uwgen.yaml").write_text(text)
    return generate(folder, f"uwgen_fp_{name}", manifest=folder / "uwgen.yaml").TOPICS[4].fingerprint


def test_field_encodings_are_part_of_the_schema_fingerprint(tmp_path):
    base = fingerprint_of(tmp_path, "base", "linear.x: {min: -2, max: 2, precision: 2}")
    assert fingerprint_of(tmp_path, "same", "linear.x: {min: -2, max: 2, precision: 2}") == base
    assert fingerprint_of(tmp_path, "finer", "linear.x: {min: -2, max: 2, precision: 3}") != base
    assert fingerprint_of(tmp_path, "clamp", "linear.x: {min: -2, max: 2, precision: 2, out_of_range: clamp}") \
        == base   # clamping happens on the sender only: the bytes mean the same
    assert fingerprint_of(tmp_path, "static", "linear.x: {static: 0}") != base
