"""Topic and service names are checked by the same rules as rcl's full-name validation."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.manifest.loader import validate_ros_name

rclpy_names = pytest.importorskip("rclpy.validate_full_topic_name")
InvalidTopicNameException = pytest.importorskip("rclpy.exceptions").InvalidTopicNameException


def rclpy_accepts(name: str) -> bool:
    try:
        rclpy_names.validate_full_topic_name(name)
        return True
    except InvalidTopicNameException:
        return False


@pytest.mark.parametrize("name", ["/a", "/turtle1/cmd_vel", "/_private/x_1", "/A/B", "/a__b"])
def test_valid_names(name):
    assert validate_ros_name(name) is None
    assert rclpy_accepts(name)


@pytest.mark.parametrize("name", ["", "a", "/", "/a/", "//a", "/a//b", "/1a", "/a/2b", "/a-b", "/a b", "/~/a", "/{x}", "/é"])
def test_invalid_names(name):
    assert validate_ros_name(name) is not None
    assert not rclpy_accepts(name)


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet="/ab_1Z-~{}. ", max_size=12))
def test_agrees_with_rclpy_on_generated_names(name):
    assert (validate_ros_name(name) is None) == rclpy_accepts(name), name
