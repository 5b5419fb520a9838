"""Decoders build rclpy messages two ways, and both give exactly rclpy's messages.

The fast way fills the slots of a bare instance; it is taken only for classes whose layout
uwgen.runtime.wire.rosclasses checked. The constructor way is the fallback. Every installed
type is decoded both ways and checked against rclpy's own serializer: the decoded message
serializes to CDR that rclpy reads back as the original, and it holds in every slot what
rclpy's own deserializer puts there (container types, dtypes, typecodes). CDR bytes are not
compared directly: rclpy's serializer leaves its alignment padding uninitialized.
"""
from __future__ import annotations

import logging

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from uwgen.codegen.rosidl_layout import ros_layout
from uwgen.idl.loader import InterfaceLibrary
from uwgen.runtime.wire.codec import load_items
from uwgen.runtime.wire.rosclasses import RosClasses, layout_problem

from .rosvalues import VARIANTS, fill, normalize
from .test_roundtrip_installed import MESSAGES, SERVICES, rclpy_class

PATHS = ("slots", "constructor")


def namespaces(allcodecs) -> dict[str, RosClasses]:
    ros = allcodecs._classes.ROS
    return {"slots": ros, "constructor": ros.constructors_only()}


def decode_with(codec, payload: bytes, header_len: int, ns):
    v = load_items(payload)
    msg, i = codec.dec(v, header_len, ns)
    assert i == len(v)
    return msg


def assert_same_as_rclpy(allcodecs, type_name: str, msg, path: str, header: list) -> None:
    codec = allcodecs.codec(type_name)
    ns = namespaces(allcodecs)[path]
    # The fast path is really the one taken for every installed type, and only there.
    assert getattr(ns, f"fast_{codec.class_key}") is (path == "slots")
    back = decode_with(codec, codec.encode(msg, list(header)), len(header), ns)
    assert_like_rclpy(back, msg)
    # The decoded message is an ordinary one: its fields can be set and read as usual.
    fields = list(type(msg).get_fields_and_field_types())
    if fields:
        setattr(back, fields[0], getattr(msg, fields[0]))
        assert_like_rclpy(back, msg)


def assert_like_rclpy(back, msg) -> None:
    cls = type(msg)
    assert type(back) is cls
    cdr = serialize_message(back)
    assert len(cdr) == len(serialize_message(msg))
    assert normalize(deserialize_message(cdr, cls)) == normalize(msg)
    assert slot_kinds(back) == slot_kinds(deserialize_message(serialize_message(msg), cls))


def slot_kinds(value):
    """What every slot of a message holds, recursively: types, numpy dtypes, array codes."""
    fields = getattr(type(value), "_fields_and_field_types", None)
    if fields is not None:
        return (type(value).__name__, value._check_fields,
                tuple((name, slot_kinds(getattr(value, "_" + name))) for name in fields))
    if type(value) is list:
        return ["list", *(slot_kinds(v) for v in value)]
    return (type(value).__name__, str(getattr(value, "dtype", "")), getattr(value, "typecode", ""))


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("type_name", MESSAGES)
def test_decoded_message_serializes_like_rclpy_both_ways(allcodecs, type_name, variant, path):
    assert_same_as_rclpy(allcodecs, type_name, fill(rclpy_class(type_name), variant), path, [0, 42])


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("type_name", SERVICES)
def test_decoded_service_parts_serialize_like_rclpy_both_ways(allcodecs, type_name, path):
    srv = getattr(rclpy_class(type_name), type_name.split("/")[2])
    for variant in VARIANTS:
        assert_same_as_rclpy(allcodecs, type_name + "_Request", fill(srv.Request, variant), path, [2, 9, 330])
        assert_same_as_rclpy(allcodecs, type_name + "_Response", fill(srv.Response, variant), path, [3, 9, 7])


def test_a_class_laid_out_otherwise_falls_back_to_its_constructor(allcodecs, caplog):
    """A layout that does not match rclpy's (as after a rosidl change) turns the fast path
    off for that class and every class that inlines it; decoding stays exact."""
    from geometry_msgs.msg import Twist

    ros = allcodecs._classes.ROS
    layouts = dict(allcodecs._classes.LAYOUTS)
    name, _rtype, store = layouts["geometry_msgs__Vector3"][0]
    layouts["geometry_msgs__Vector3"] = ((name, "float", store), *layouts["geometry_msgs__Vector3"][1:])
    changed = RosClasses(ros._imports, ros._fallback, layouts)
    with caplog.at_level(logging.WARNING, logger="uwgen.codec"):
        assert changed.fast_geometry_msgs__Twist is False
    assert "geometry_msgs__Vector3 is not laid out as uwgen's fast decoders assume" in caplog.text
    assert changed.fast_std_msgs__Header is True          # other classes keep the fast path
    msg = Twist()
    msg.linear.x, msg.angular.z = 0.5, -0.25
    codec = allcodecs.codec("geometry_msgs/msg/Twist")
    back = decode_with(codec, codec.encode(msg, [0, 1]), 2, changed)
    assert_like_rclpy(back, msg)


def test_layout_check_names_what_differs():
    from geometry_msgs.msg import Vector3
    from sensor_msgs.msg import LaserScan

    lib = InterfaceLibrary([], installed=True)
    vector = ros_layout(lib.get("geometry_msgs/msg/Vector3"))
    scan = ros_layout(lib.get("sensor_msgs/msg/LaserScan"))
    assert layout_problem(Vector3, vector, check_fields=False) == ""
    assert layout_problem(LaserScan, scan, check_fields=False) == ""

    class Wider(Vector3):
        __slots__ = ["_w"]
    assert layout_problem(Wider, vector, check_fields=False).startswith("slots")
    assert "check_fields" in layout_problem(Vector3, vector, check_fields=True)
    ranges = [f for f in scan if f[0] == "ranges"][0]
    wrong = tuple((*f[:2], "list") if f is ranges else f for f in scan)
    assert layout_problem(LaserScan, wrong, check_fields=False) == "slot _ranges holds array, not list"
