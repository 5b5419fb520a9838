"""Two real bridges over the emulator, built from manifests that differ in one thing that
changes the bytes of one id: that id is refused and reported, nothing misread is
published, and the ids both sides agree on still flow."""
from __future__ import annotations

import time

import pytest
from geometry_msgs.msg import Accel, Twist
from std_msgs.msg import String
from std_srvs.srv import SetBool

from uwgen.bridge.plan import import_package

from bridge.fakes import wait_for

from .conftest import MANIFEST, network

SCHEMA_ID = 249
BASE = MANIFEST.replace("fragment_id: 250\n", f"fragment_id: 250\nschema_id: {SCHEMA_ID}\n")
CMD_TYPE = "    type: geometry_msgs/msg/Twist\n"

# One change to the /cmd_vel entry (id 4) of the vehicle's manifest, with the ROS type the
# vehicle's side then has on /cmd_vel. Accel has the same shape as Twist (two Vector3s):
# without fingerprints the vehicle would publish the surface's velocity command as an
# acceleration. A field-precision difference drops in here as one more case once
# `fields:` encodings exist in the manifest.
DIFFERENCES = {
    "type": (CMD_TYPE, "    type: geometry_msgs/msg/Accel\n", Accel),
}


def build(root, name: str, manifest: str):
    from uwgen.cli import main as uwgen_main
    folder = root / name / "interfaces"
    (folder / "e2e_msgs" / "msg").mkdir(parents=True)
    (folder / "e2e_msgs" / "msg" / "Note.msg").write_text("string text\n")
    (folder / "uwgen.yaml").write_text(manifest.replace("package: uwgen_e2e", f"package: {name}"))
    out = root / name / "generated" / name
    assert uwgen_main(["build", str(folder), "-o", str(out)]) == 0
    return import_package(name, root / name / "generated")


@pytest.fixture(scope="module")
def packages(tmp_path_factory):
    root = tmp_path_factory.mktemp("schema")
    surface = build(root, "uwgen_e2e_fp_surface", BASE)
    vehicles = {}
    for key, (old, new, _cls) in DIFFERENCES.items():
        assert BASE.count(old) == 1
        vehicles[key] = build(root, f"uwgen_e2e_fp_vehicle_{key}", BASE.replace(old, new))
    return surface, vehicles


def heard(bridge, ident: int) -> bool:
    return str(ident) in bridge.status()["schema"]["heard"]


@pytest.mark.parametrize("difference", sorted(DIFFERENCES))
def test_mismatching_id_is_refused_and_matching_ids_flow(packages, difference):
    surface_pkg, vehicles = packages
    vehicle_pkg = vehicles[difference]
    vehicle_cls = DIFFERENCES[difference][2]
    assert surface_pkg.TOPICS[4].fingerprint != vehicle_pkg.TOPICS[4].fingerprint
    assert surface_pkg.TOPICS[7].fingerprint == vehicle_pkg.TOPICS[7].fingerprint
    assert surface_pkg.SCHEMA_DIGEST != vehicle_pkg.SCHEMA_DIGEST

    with network(surface_pkg, bridges=()) as net:
        net.start_bridge("surface")
        net.package = vehicle_pkg
        net.start_bridge("vehicle")
        surface, vehicle = net.bridges["surface"], net.bridges["vehicle"]

        misread = []
        net.vehicle.node("sim").create_subscription(vehicle_cls, "/cmd_vel", misread.append, 10)
        logs = []
        net.surface.node("op").create_subscription(String, "/log", logs.append, 10)
        net.vehicle.node("server").create_service(
            SetBool, "/enable", lambda req, resp: setattr(resp, "success", req.data) or resp)
        cmd_pub = net.surface.node("op_pub").create_publisher(Twist, "/cmd_vel", 10)
        log_pub = net.vehicle.node("sim_pub").create_publisher(String, "/log", 10)
        client = net.surface.node("caller").create_client(SetBool, "/enable")

        # Each side hears the other's announcement (sent at connect, ahead of data).
        wait_for(lambda: net.connected() and heard(vehicle, 4)
                 and heard(surface, 7), what="schema announcements")
        wait_for(lambda: cmd_pub.get_subscription_count() and log_pub.get_subscription_count(),
                 what="bridges subscribed")

        twist = Twist()
        twist.linear.x, twist.angular.z = 0.5, -0.25
        for _ in range(3):
            cmd_pub.publish(twist)
            time.sleep(0.3)                      # latest queue, rate 5: each one is sent
        log_pub.publish(String(data="vehicle ready"))
        assert client.wait_for_service(timeout_sec=5.0)
        future = client.call_async(SetBool.Request(data=True))

        wait_for(lambda: logs and future.done(), what="the matching topic and service")
        assert logs[0].data == "vehicle ready"
        assert future.result().success is True
        wait_for(lambda: vehicle.status()["schema"]["refused"] >= 1 or misread,
                 what="/cmd_vel frames at the vehicle")
        assert misread == []                     # nothing was decoded as the wrong type
        assert vehicle.status()["schema"]["refused"] >= 1

        status = vehicle.status()
        mismatch = status["schema"]["mismatched"]
        assert set(mismatch) == {"4"}
        assert mismatch["4"]["name"] == "/cmd_vel"
        assert mismatch["4"]["ours"] == vehicle_pkg.TOPICS[4].fingerprint.hex()
        assert mismatch["4"]["theirs"] == surface_pkg.TOPICS[4].fingerprint.hex()
        assert status["topics"]["/cmd_vel"]["received"] == 0          # refused before decoding
        assert status["topics"]["/cmd_vel"]["decode_errors"] == 0
        assert surface.status()["topics"]["/cmd_vel"]["link"]["sent"] >= 1
        # The surface, which sends id 4, learns that the vehicle refuses it (it receives
        # nothing on id 4, so it refuses nothing itself).
        on_surface = surface.status()["schema"]["mismatched"]
        assert set(on_surface) == {"4"} and on_surface["4"]["refused"] == 0
        assert on_surface["4"]["theirs"] == vehicle_pkg.TOPICS[4].fingerprint.hex()
