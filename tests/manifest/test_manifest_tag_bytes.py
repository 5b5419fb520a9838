"""The manifest's `security: {tag_bytes}`: the per-packet tag length, 4, 6 or 8 (default 8),
refused where it does not apply (wire format 1) and every mistake located."""
from __future__ import annotations

import pytest

from .helpers import error_of, load_text

HEAD = """
        network: demo
        security: {mode: encrypt, key_file: keys/demo.key, tag_bytes: 6}
        sides:
          surface: {port: 4000, sender_id: 1}
          vehicle: {port: 4001, sender_id: 2}
        topics:
          - {name: /cmd, id: 4, type: geometry_msgs/msg/Twist, publisher: surface}
          - {name: /raw, id: 8, type: std_msgs/msg/String, publisher: vehicle, security: off}
"""


@pytest.mark.parametrize("value", [4, 6, 8])
def test_each_allowed_length_reaches_the_security_plan(tmp_path, value):
    m = load_text(tmp_path, HEAD.replace("tag_bytes: 6", f"tag_bytes: {value}"))
    assert m.security.tag_bytes == value
    assert m.security_plan().tag_bytes == value


def test_without_the_key_the_tag_is_8_bytes(tmp_path):
    m = load_text(tmp_path, HEAD.replace(", tag_bytes: 6", ""))
    assert m.security.tag_bytes == 8 and m.security_plan().tag_bytes == 8


@pytest.mark.parametrize("value", ["5", "16", "2", "0", "-4", "eight", "8.0", "true", "[8]", "null"])
def test_another_value_is_located_with_the_allowed_ones(tmp_path, value):
    err = error_of(tmp_path, HEAD.replace("tag_bytes: 6", f"tag_bytes: {value}"))
    assert (err.where.line, err.where.column) == (2, 63)
    assert "security tag_bytes must be one of 4, 6, 8" in err.message
    assert repr(value) in err.message or value == "[8]"


RMW = HEAD.replace("security: off}", "security: off, profile: rmw_desert}")


def test_a_wire_format_1_link_refuses_a_short_tag_where_it_is_written(tmp_path):
    err = error_of(tmp_path, RMW.replace("tag_bytes: 6", "tag_bytes: 4"))
    assert (err.where.line, err.where.column) == (2, 63)
    assert "tag_bytes 4 applies to wire format 4 links only" in err.message
    assert "/raw (line 8) is in profile rmw_desert" in err.message
    assert "8-byte tag" in err.message


def test_a_wire_format_1_link_takes_the_8_it_has(tmp_path):
    m = load_text(tmp_path, RMW.replace("tag_bytes: 6", "tag_bytes: 8"))
    assert m.uses_rmw_desert() and m.security_plan().tag_bytes == 8
