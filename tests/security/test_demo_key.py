"""The demo's secure link: its key is made when missing (never committed, owner-only, in the
cache for a read-only checkout, one demo at a time), and a bridge set up exactly as the demo
sets up its vehicle refuses a stranger's cmd_vel and accepts the surface's."""
from __future__ import annotations

import stat
from pathlib import Path

import pytest

from uwgen.demo import keys as demo_keys
from uwgen.demo.keys import demo_key
from uwgen.security.keys import SecurityError, read_key_file, write_key_file

ROOT = Path(__file__).resolve().parents[2]
MANIFEST = "network: n\nsecurity: {mode: encrypt, key_file: keys/demo.key}\nsides: {a: {port: 4000}}\n"


def manifest(folder: Path, text: str = MANIFEST) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "uwgen.yaml"
    path.write_text(text)
    return path


def test_missing_key_is_created_owner_only_next_to_the_manifest_then_reused(tmp_path):
    m = manifest(tmp_path / "samples")
    with demo_key(m, tmp_path / "out") as key:
        assert key.path == tmp_path / "samples" / "keys" / "demo.key" and key.created
        assert stat.S_IMODE(key.path.stat().st_mode) == 0o600
        assert key.bridge_args() == ["--key-file", str(key.path)]
        assert "created now" in key.describe() and str(key.path) in key.describe()
        first = read_key_file(key.path)
    with demo_key(m, tmp_path / "out") as again:
        assert again.path == key.path and not again.created and "existing" in again.describe()
        assert read_key_file(again.path) == first          # never replaced


def test_read_only_checkout_keeps_its_key_in_uwgens_cache(tmp_path, monkeypatch):
    m = manifest(tmp_path / "samples")
    monkeypatch.setenv("UWGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(demo_keys.os, "access", lambda path, mode: Path(path) == tmp_path / "cache"
                        or tmp_path / "cache" in Path(path).parents)
    with demo_key(m, tmp_path / "out") as key:
        assert key.path == tmp_path / "cache" / "demo" / "keys" / "demo.key" and key.created
        assert "read-only" in key.describe()
    assert not (tmp_path / "samples" / "keys").exists()


def test_a_second_demo_at_once_gets_a_key_of_its_own_never_the_same_state(tmp_path):
    # Two demos on one key would reserve the same sequence numbers in two processes.
    m = manifest(tmp_path / "samples")
    with demo_key(m, tmp_path / "out1") as first:
        with demo_key(m, tmp_path / "out2") as second:
            assert second.path == tmp_path / "out2" / "keys" / "demo.key"
            assert read_key_file(second.path) != read_key_file(first.path)
            assert "another demo is using" in second.describe()
    with demo_key(m, tmp_path / "out3") as third:           # released: the shared key again
        assert third.path == first.path


def test_a_key_others_can_read_stops_the_demo_with_the_reason(tmp_path):
    m = manifest(tmp_path / "samples")
    key = write_key_file(tmp_path / "samples" / "keys" / "demo.key")
    assert key
    (tmp_path / "samples" / "keys" / "demo.key").chmod(0o644)
    with pytest.raises(SecurityError, match="chmod 600"):
        with demo_key(m, tmp_path / "out"):
            pass


def test_a_manifest_without_security_needs_no_key(tmp_path):
    m = manifest(tmp_path / "samples", "network: n\nsides: {a: {port: 4000}}\n")
    with demo_key(m, tmp_path / "out") as key:
        assert key is None
    assert not (tmp_path / "samples" / "keys").exists()


def test_the_demo_manifest_names_a_key_inside_the_git_ignored_folder():
    from uwgen.commands.demo import DEMO_MANIFEST
    assert demo_keys.manifest_key_file(DEMO_MANIFEST) == ROOT / "msg_samples" / "keys" / "demo.key"


# -- the demo's vehicle bridge, as `uwgen demo` starts it ---------------------------------

@pytest.fixture
def demo_guards(tmp_path):
    """The vehicle's and the surface's LinkGuard from the generated demo package, the key
    given with --key-file as the demo does."""
    from uwgen.bridge.plan import BridgePlan, import_package
    from uwgen.bridge.security import guard_for
    pkg = import_package("uwgen_demo", ROOT / "generated")
    write_key_file(tmp_path / "demo.key")
    guards = {}
    for side in ("vehicle", "surface"):
        plan = BridgePlan.from_package(pkg, side)
        guards[side] = guard_for(plan, plan.options(key_file=tmp_path / "demo.key"))
    yield pkg, guards
    for g in guards.values():
        g.close()


def cmd_vel(pkg, x: float) -> bytes:
    from geometry_msgs.msg import Twist
    t = Twist()
    t.linear.x = x
    return pkg.TOPICS[4].encode(t)


def test_demo_vehicle_drops_a_strangers_cmd_vel_and_takes_the_surfaces(demo_guards, tmp_path):
    # The demo's links speak wire format 2: one tag per packet (PacketSeal).
    from uwgen.runtime.wire import envelope as env
    from uwgen.security.guard import GuardConfig
    from uwgen.security.packet_seal import PacketSeal

    from .packets import Side
    pkg, guards = demo_guards
    vehicle, surface = Side(guards["vehicle"], 2), Side(guards["surface"], 1)
    # The forgery the seal stops: a plain packet with a cmd_vel, as anyone reaching the vehicle's port could write.
    plain = env.Envelope(1, 0, (env.from_v1(cmd_vel(pkg, 1.5)),)).encode()
    assert vehicle.receive(plain) == []
    # One sealed under another key, claiming the surface's sender id.
    stranger = Side(PacketSeal(bytes(32), GuardConfig("demo", 1, {2: "vehicle"}, {4: "encrypt"}, {}),
                               name="stranger"), 1)
    assert vehicle.receive(stranger.send(cmd_vel(pkg, 1.5))) == []
    stats = vehicle.stats()
    assert stats["unprotected"] == 1 and stats["bad_tag"] == 1 and stats["verified"] == 0
    # The surface's own command: encrypted (its x is not readable on the wire), delivered.
    genuine = cmd_vel(pkg, 1.5)
    sealed = surface.send(genuine)
    assert len(sealed) >= len(genuine) + 8 and genuine[3:] not in sealed
    assert vehicle.receive(sealed) == [genuine] and vehicle.stats()["verified"] == 1


def test_demo_battery_signed_still_fits_one_packet(demo_guards):
    # The manifest omits what the simulated vehicle does not measure so that signing the
    # battery does not split it into two fragments (64-byte packets, 4-byte frame overhead),
    # even in a sync packet that asks for a sync (the most the seal adds: 23 bytes).
    from sensor_msgs.msg import BatteryState
    from uwgen.runtime.wire.envelope import HEAD, v1_message_size
    from uwgen.runtime.wire.framing import OVERHEAD
    from uwgen.security.packet_seal import MAX_OVERHEAD
    pkg, guards = demo_guards
    b = BatteryState()
    b.header.stamp.sec, b.header.stamp.nanosec, b.header.frame_id = 1795433581, 999999999, "vehicle"
    b.voltage, b.current, b.percentage, b.present, b.power_supply_status = 16.8, -5.5, 1.0, True, 2
    payload = pkg.TOPICS[6].encode(b)
    worst = OVERHEAD + HEAD + MAX_OVERHEAD + v1_message_size(payload, last=True)
    assert worst <= pkg.MANIFEST.sides["vehicle"].link.max_read_length


def test_a_given_key_file_is_used_instead_of_the_manifests(tmp_path):
    m = manifest(tmp_path / "samples")
    given = tmp_path / "elsewhere" / "net.key"
    with demo_key(m, tmp_path / "out", given) as key:
        assert key.path == given and key.created
        assert given.with_name("net.key.lock").exists()
    assert not (tmp_path / "samples" / "keys").exists()     # the manifest's key was not made
