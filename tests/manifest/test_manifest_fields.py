"""Field encodings in the manifest (`fields:`, `request_fields:`, `response_fields:`):
what is read, and every mistake refused at its file:line:column."""
from __future__ import annotations

from fractions import Fraction

import pytest

from tests.manifest.helpers import SIDES, error_of, load_text


def topic(type_name: str, fields: str, profile: str = "") -> str:
    extra = f"\n            profile: {profile}" if profile else ""
    return SIDES + f"""
        topics:
          - name: /t
            id: 4
            type: {type_name}
            publisher: surface{extra}
            fields:
{fields}
"""


def line_of(text: str, needle: str) -> int:
    """1-based line of the first line holding `needle` in the manifest as written."""
    import textwrap
    lines = textwrap.dedent(text).lstrip("\n").splitlines()
    return next(k for k, line in enumerate(lines, 1) if needle in line)


def test_numbers_are_read_as_the_exact_decimals_written(tmp_path):
    m = load_text(tmp_path, topic("geometry_msgs/msg/Twist", """
              linear.x: {min: -2, max: 2, precision: 1}
              angular.z: {min: -3.2, max: 3.2, resolution: 0.1, out_of_range: clamp}"""))
    x, z = m.topics[0].fields
    assert (x.kind, x.min, x.max, x.step, x.clamp) == ("quantize", -2, 2, Fraction(1, 10), False)
    assert (z.min, z.step, z.clamp, z.count) == (Fraction(-32, 10), Fraction(1, 10), True, 65)
    assert x.where.line == line_of(topic("geometry_msgs/msg/Twist", "\n              linear.x: {"), "linear.x:")


def test_every_kind_of_encoding_is_read(tmp_path):
    m = load_text(tmp_path, topic("sensor_msgs/msg/BatteryState", """
              header.stamp: {time: day, resolution: 0.5}
              header.frame_id: {static: bat}
              cell_voltage: {max_count: 8}
              cell_voltage[]: {min: 0, max: 5, precision: 2}
              power_supply_status: {values: [0, 1, 2, 4]}
              location: {max_length: 8}
              serial_number: {omit: true}"""))
    kinds = {f.path: f.kind for f in m.topics[0].fields}
    assert kinds == {"header.stamp": "time_of_day", "header.frame_id": "static", "cell_voltage": "max_count",
                     "cell_voltage[]": "quantize", "power_supply_status": "enum", "location": "max_length",
                     "serial_number": "omit"}
    stamp = m.topics[0].fields[0]
    assert stamp.count == 172800


def test_services_take_request_and_response_fields_separately(tmp_path):
    m = load_text(tmp_path, SIDES + """
        services:
          - name: /tp
            id: 20
            type: turtlesim/srv/TeleportAbsolute
            server: vehicle
            request_fields:
              x: {min: 0, max: 12, precision: 2}
            response_fields: {}
""")
    s = m.services[0]
    assert [f.path for f in s.request_fields] == ["x"] and s.response_fields == ()


@pytest.mark.parametrize("fields, line, text", [
    ("              linear.w: {static: 0}", 11, "geometry_msgs/msg/Vector3 has no field 'w'"),
    ("              linear.x.y: {static: 0}", 11, "linear.x is a float64, which has no fields"),
    ("              linear[]: {static: 0}", 11, "'[]' needs an array"),
    ("              linear.x: {min: 2, max: 1, precision: 1}", 11, "min of field linear.x of topic /t must be below max"),
    ("              linear.x: {min: 0, max: 1, resolution: 0.3}", 11, "does not divide its range"),
    ("              linear.x: {min: 0, max: 1}", 11, "give precision (decimal places) or resolution"),
    ("              linear.x: {min: 0, max: 1, precision: 1, out_of_range: wrap}", 11, "out_of_range of field linear.x"),
    ("              linear.x: {precision: 1}", 11, "needs 'min' and 'max'"),
    ("              linear.x: {min: 0, max: 1, precision: 1, static: 0}", 11, "cannot be combined"),
    ("              linear.x: {static: abc}", 11, "must be a number for a float64 field"),
    ("              linear: {min: 0, max: 1, precision: 1}", 11, "needs a number or string field"),
    ("              linear.x: {time: day}", 11, "needs a builtin_interfaces/msg/Time field"),
    ("              linear.x: {max_length: 3}", 11, "needs a string field"),
    ("              linear.x: {omit: false}", 11, "must be true"),
    ("              linear.x: {}", 11, "says nothing"),
    ("              linear.x: {minimum: 0}", 11, "unknown key 'minimum'"),
    ("              linear: {omit: true}\n              linear.x: {static: 1}", 12, "overlaps 'linear'"),
])
def test_twist_mistakes_are_located(tmp_path, fields, line, text):
    text_written = topic("geometry_msgs/msg/Twist", fields)
    error = error_of(tmp_path, text_written)
    assert text in error.message
    assert error.where.line == line_of(text_written, "fields:") + line - 10


@pytest.mark.parametrize("fields, line, text", [
    ("              power_supply_status: {static: 300}", 11, "outside the uint8 range 0..255"),
    ("              power_supply_status: {min: 0, max: 300}", 11, "outside the uint8 range"),
    ("              power_supply_status: {min: 0, max: 10, resolution: 0.5}", 11, "must be integers"),
    ("              power_supply_status: {values: [1, 2, 1]}", 11, "listed twice"),
    ("              power_supply_status: {values: [1, 256]}", 11, "outside the uint8 range"),
    ("              present: {values: [0, 1]}", 11, "a bool already takes one bit"),
    ("              cell_voltage: {min: 0, max: 5, precision: 2}", 11, "write the path with '[]'"),
    ("              cell_voltage[]: {max_count: 3}", 11, "needs a sequence"),
    ("              cell_voltage: {max_count: -1}", 11, "must be >= 0"),
    ("              header.stamp: {time: day, resolution: 7}", 11, "does not divide a day"),
    ("              header.stamp: {time: epoch, span: 100}", 11, "missing the required key 'epoch'"),
    ("              header.stamp: {time: epoch, epoch: 1700000000, span: 10000000000}", 11, "passes the int32 seconds"),
    ("              header.stamp: {time: week}", 11, "time of field header.stamp"),
    ("              header: {static: 0}", 11, "std_msgs/msg/Header message"),
    ("              voltage: {min: 0, max: 1.0e+39, resolution: 1.0e+30}", 11, "outside the float32 range"),
    ("              cell_voltage[]: {static: 0}", 11, "applies to a whole field: name the array 'cell_voltage'"),
    ("              cell_voltage[]: {values: [1.5, 3.0]}\n              cell_voltage[]: {omit: true}", 12,
     "duplicate key 'cell_voltage[]'"),
])
def test_battery_mistakes_are_located(tmp_path, fields, line, text):
    text_written = topic("sensor_msgs/msg/BatteryState", fields)
    error = error_of(tmp_path, text_written)
    assert text in error.message
    assert error.where.line == line_of(text_written, "fields:") + line - 10


def test_service_paths_are_checked_against_their_own_part(tmp_path):
    error = error_of(tmp_path, SIDES + """
        services:
          - name: /s
            id: 20
            type: turtlesim/srv/Spawn
            server: vehicle
            response_fields:
              name: {max_length: 0}
              x: {static: 0}
""")
    assert "of the response of service /s: turtlesim/srv/Spawn_Response has no field 'x'" in error.message


@pytest.mark.parametrize("encoding, text", [
    ("{min: 0, max: 3}", "need a number field, and the field is a byte"),
    ("{values: [0, 1]}", "a byte field holds an octet"),
])
def test_byte_fields_take_no_numeric_encodings(tmp_path, encoding, text):
    error = error_of(tmp_path, topic("diagnostic_msgs/msg/DiagnosticStatus", f"              level: {encoding}"))
    assert text in error.message


def test_paths_inside_arrays_of_messages_are_refused(tmp_path):
    error = error_of(tmp_path, topic("diagnostic_msgs/msg/DiagnosticArray", "              status.level: {values: [0, 1]}"))
    assert "status is an array of messages; encodings inside arrays of messages are not supported" in error.message


def test_static_fixed_array_length_is_checked(tmp_path):
    error = error_of(tmp_path, topic("sensor_msgs/msg/NavSatFix", "              position_covariance: {static: [0, 0]}"))
    assert "2 elements; the field is a float64[9]" in error.message


def test_rmw_desert_refuses_field_encodings(tmp_path):
    error = error_of(tmp_path, topic("geometry_msgs/msg/Twist", "              linear.x: {static: 0}",
                                     profile="rmw_desert"))
    assert "profile rmw_desert cannot carry field encodings" in error.message
    assert error.where.line == line_of(topic("geometry_msgs/msg/Twist", "", profile="rmw_desert"), "fields:")


def test_packed_is_a_profile(tmp_path):
    m = load_text(tmp_path, topic("geometry_msgs/msg/Twist", "              linear.x: {static: 0}", profile="packed"))
    assert m.topics[0].profile == "packed"


def test_reference_manifest_documents_every_encoding_key():
    from tests.manifest.helpers import SAMPLES
    from uwgen.manifest.fields import ENCODING_KEYS
    text = (SAMPLES / "manifest-reference.yaml").read_text()
    for key in ENCODING_KEYS:
        assert f"{key}:" in text, key
