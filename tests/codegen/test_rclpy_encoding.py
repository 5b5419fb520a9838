"""Encoders read rclpy messages two ways, and both put the same bytes on the wire.

The fast way (`enc_*_slots`) reads each field's slot (`m._x`) instead of its property;
TypeCodec.encode takes it only for messages of an rclpy class whose layout (and its
nested classes') uwgen.runtime.wire.rosclasses checked, and goes back to the encoder that reads
fields by name when a nested value is no rclpy message. Every installed type is encoded
both ways: the payloads are identical, and what they decode to serializes like the
original under rclpy's own serializer.
"""
from __future__ import annotations

import dataclasses

import pytest
from geometry_msgs.msg import Point, Pose, PoseArray, Twist, Vector3

from uwgen.runtime.wire.codec import EncodeError

from .rosvalues import VARIANTS, fill
from .test_rclpy_construction import assert_like_rclpy, decode_with
from .test_roundtrip_installed import MESSAGES, SERVICES, rclpy_class


def by_name(codec):
    """The same codec where no class passed the layout check: every message by name."""
    return dataclasses.replace(codec, ros=codec.ros.constructors_only(), _slots_for=[])


def assert_both_ways_like_rclpy(codec, msg, header: list) -> None:
    assert codec.slots_class() is type(msg)                 # the fast way is the one taken
    slow = by_name(codec)
    assert slow.slots_class() is None
    fast_items, slow_items = list(header), list(header)
    codec.enc_slots(msg, fast_items)
    codec.enc(msg, slow_items)
    assert repr(fast_items) == repr(slow_items)      # (repr: NaN is not equal to itself)
    payload = codec.encode(msg, list(header))
    assert payload == slow.encode(msg, list(header))
    assert_like_rclpy(decode_with(codec, payload, len(header), codec.ros), msg)


@pytest.mark.parametrize("type_name", MESSAGES)
def test_message_encodes_the_same_from_slots_and_by_name(allcodecs, type_name):
    for variant in VARIANTS:
        assert_both_ways_like_rclpy(allcodecs.codec(type_name), fill(rclpy_class(type_name), variant), [0, 42])


@pytest.mark.parametrize("type_name", SERVICES)
def test_service_parts_encode_the_same_from_slots_and_by_name(allcodecs, type_name):
    srv = getattr(rclpy_class(type_name), type_name.split("/")[2])
    for variant in VARIANTS:
        assert_both_ways_like_rclpy(allcodecs.codec(type_name + "_Request"), fill(srv.Request, variant), [2, 9, 1])
        assert_both_ways_like_rclpy(allcodecs.codec(type_name + "_Response"), fill(srv.Response, variant), [3, 9, 1])


def test_the_rmw_desert_profile_has_slot_encoders_too(allcodecs):
    codec = allcodecs.codec("geometry_msgs/msg/Twist", "rmw_desert")
    msg = Twist(linear=Vector3(x=1.5), angular=Vector3(z=-0.25))
    assert_both_ways_like_rclpy(codec, msg, [0, 3])


def test_a_nested_value_that_is_no_rclpy_message_is_read_by_name(allcodecs):
    """rclpy stores what it is given when ROS_PYTHON_CHECK_FIELDS is off: a plain object
    with the right fields encodes as it always did (the slot reads fail; by name works)."""
    codec = allcodecs.codec("geometry_msgs/msg/Twist")
    plain = allcodecs._classes.PLAIN.geometry_msgs__Vector3(x=2.0, y=0.5, z=-1.0)
    msg = Twist()
    msg._linear = plain
    expected = codec.encode(Twist(linear=Vector3(x=2.0, y=0.5, z=-1.0)), [0, 1])
    assert codec.encode(msg, [0, 1]) == expected


def test_an_array_element_of_another_kind_is_read_by_name_or_named_in_the_error(allcodecs):
    codec = allcodecs.codec("geometry_msgs/msg/PoseArray")
    plain_pose = allcodecs._classes.PLAIN.geometry_msgs__Pose()
    plain_pose.position.x = 4.0
    msg = PoseArray(poses=[Pose(position=Point(x=1.0)), Pose()])
    msg._poses = [msg.poses[0], plain_pose]
    expected = codec.encode(PoseArray(poses=[Pose(position=Point(x=1.0)), Pose(position=Point(x=4.0))]), [0, 1])
    assert codec.encode(msg, [0, 1]) == expected
    msg._poses = [Pose(), "not a pose"]
    with pytest.raises(EncodeError) as err:
        codec.encode(msg, [0, 1])
    assert err.value.path.startswith("poses[1]")
