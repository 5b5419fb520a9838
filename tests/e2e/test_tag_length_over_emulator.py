"""Two real bridges over the emulator whose manifest chooses the per-packet tag length
(`security: {tag_bytes}`, docs/wire-format.md section 12.2): with 4-byte tags on both sides the
commands flow, each packet ending in a 4-byte tag; built with different lengths, the vehicle
refuses every packet of the surface, names both lengths once (`tag_length`), and nothing
reaches ROS."""
from __future__ import annotations

import logging
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import Twist, Vector3

from uwgen.runtime.wire import envelope as env

from bridge.fakes import wait_for

from .conftest import network
from .test_secure_bridges import MANIFEST, build, cmd_vel_ends, security


def with_tag(n: int) -> str:
    text = MANIFEST.replace("key_file: net.key}", f"key_file: net.key, tag_bytes: {n}}}")
    assert text != MANIFEST
    return text


@pytest.fixture(scope="module")
def tag4(tmp_path_factory):
    return build(tmp_path_factory, with_tag(4), "uwgen_e2etag4")


@pytest.fixture(scope="module")
def tag8(tmp_path_factory):
    return build(tmp_path_factory, with_tag(8), "uwgen_e2etag8")


def key_of(package) -> Path:
    return Path(package.MANIFEST.source).parent / "net.key"


def test_four_byte_tags_carry_the_commands(tag4):
    assert tag4.MANIFEST.security.tag_bytes == 4
    with network(tag4) as net:
        got, pub, heard = cmd_vel_ends(net)
        for k in range(3):
            pub.publish(Twist(linear=Vector3(x=0.1 * (k + 1))))
            time.sleep(0.1)
        wait_for(lambda: len(got) == 3, timeout=10, what="the commands under 4-byte tags")
        assert [round(m.linear.x, 2) for m in got] == [0.1, 0.2, 0.3]
        packets = [env.decode(h, 4) for h in heard]
        assert packets and all(len(p.tag) == 4 for p in packets)
        assert security(net, "vehicle")["dropped"] == 0


def test_sides_built_with_different_tag_lengths_refuse_each_other_clearly(tag4, tag8, caplog):
    assert tag4.TOPICS[4].fingerprint != tag8.TOPICS[4].fingerprint      # protected: differs
    assert tag4.TOPICS[7].fingerprint != tag8.TOPICS[7].fingerprint
    with network(tag4, bridges=()) as net, caplog.at_level(logging.ERROR, logger="uwgen.security"):
        net.start_bridge("surface")
        net.package = tag8
        net.start_bridge("vehicle", key_file=key_of(tag4))              # the same network key
        got: list[Twist] = []
        net.vehicle.node("sim").create_subscription(Twist, "/cmd_vel", got.append, 50)
        pub = net.surface.node("op").create_publisher(Twist, "/cmd_vel", 10)
        # connected (the two never measure each other's clocks: they refuse each other)
        wait_for(lambda: all(b.link.stats()["connected"] for b in net.bridges.values())
                 and pub.get_subscription_count(), what="bridges up")
        deadline = time.monotonic() + 10
        while security(net, "vehicle")["tag_length"] < 3 and time.monotonic() < deadline:
            pub.publish(Twist(linear=Vector3(x=0.5)))
            time.sleep(0.1)
        sec = security(net, "vehicle")
        assert sec["tag_length"] >= 3 and sec["bad_tag"] == 0         # the epoch's sync packets
        assert sec["verified"] == 0
        assert got == []
        said = [r.getMessage() for r in caplog.records if "-byte tags" in r.getMessage()]
        # once per side: the vehicle's clock probes reach the surface, which says so too
        vehicle = [m for m in said if m.startswith("[vehicle]")]
        assert len(vehicle) == 1 and len(said) <= 2
        assert "sender 1 (surface) seals its packets with 4-byte tags, this side expects 8" in vehicle[0]
