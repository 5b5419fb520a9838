"""How a bridge finds its key and state file, and the clear errors when it cannot."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from uwgen.bridge.plan import BridgePlan, PlanError
from uwgen.bridge.security import check_security, guard_for
from uwgen.cli import main
from uwgen.manifest.model import SecurityPlan, Side
from uwgen.runtime.wire.table import ManifestInfo


def package(tmp_path, key_file="net.key", tag_bytes=8):
    manifest = ManifestInfo(network="demo", profile="native",
                            sides={"surface": Side("surface", port=4000), "vehicle": Side("vehicle", port=4001)},
                            fragment_id=None, source=str(tmp_path / "uwgen.yaml"),
                            security=SecurityPlan(key_file, {"surface": 1, "vehicle": 2}, {4: "encrypt"},
                                                  tag_bytes))
    return SimpleNamespace(MANIFEST=manifest, TOPICS={}, SERVICES={})


def test_the_key_is_found_next_to_the_manifest_and_the_state_next_to_the_key(tmp_path, caplog):
    import logging
    assert main(["keygen", str(tmp_path / "net.key")]) == 0
    plan = BridgePlan.from_package(package(tmp_path), "vehicle")
    with caplog.at_level(logging.INFO, logger="uwgen.security"):
        guard = guard_for(plan, plan.options())
    start = [r.getMessage() for r in caplog.records if "secure link" in r.getMessage()]
    assert len(start) == 1 and "sender 2" in start[0] and "4 (encrypt)" in start[0]
    from uwgen.security.keys import key_id, read_key_file
    assert key_id(read_key_file(tmp_path / "net.key"), "demo") in start[0]
    assert guard.config.sender == 2 and guard.config.peers == {1: "surface"}
    assert guard.lock_path == tmp_path / "net.key.demo.vehicle.lock"
    from uwgen.security.packet_seal import PacketSeal
    assert isinstance(guard, PacketSeal) and "one 8-byte tag per packet" in start[0]   # wire format 2, default tag


def test_the_manifests_tag_length_reaches_the_seal(tmp_path, caplog):
    import logging
    assert main(["keygen", str(tmp_path / "net.key")]) == 0
    plan = BridgePlan.from_package(package(tmp_path, tag_bytes=4), "vehicle")
    with caplog.at_level(logging.INFO, logger="uwgen.security"):
        guard = guard_for(plan, plan.options())
    from uwgen.security.packet_seal import PacketSeal
    assert isinstance(guard, PacketSeal) and guard.config.tag_bytes == 4
    assert guard.hooks().overhead == 4 + 13 + 2
    assert any("one 4-byte tag per packet" in r.getMessage() for r in caplog.records)


def test_key_file_and_state_options_override_the_manifest(tmp_path):
    assert main(["keygen", str(tmp_path / "other.key")]) == 0
    plan = BridgePlan.from_package(package(tmp_path), "surface")
    opts = plan.options(key_file=tmp_path / "other.key", security_state=tmp_path / "s.state")
    guard = guard_for(plan, opts)
    assert guard.lock_path == tmp_path / "s.state"


def test_a_missing_key_stops_the_bridge_with_a_clear_message(tmp_path):
    plan = BridgePlan.from_package(package(tmp_path), "vehicle")
    with pytest.raises(PlanError, match="not found .*: copy the network's key file there") as err:
        check_security(plan, plan.options())
    assert "create one" not in str(err.value)     # a new key would split the network


def test_a_key_others_can_read_stops_the_bridge(tmp_path):
    assert main(["keygen", str(tmp_path / "net.key")]) == 0
    (tmp_path / "net.key").chmod(0o640)
    plan = BridgePlan.from_package(package(tmp_path), "vehicle")
    with pytest.raises(PlanError, match="chmod 600"):
        guard_for(plan, plan.options())


def test_unprotected_packages_get_no_guard(tmp_path):
    pkg = package(tmp_path)
    pkg.MANIFEST = ManifestInfo("demo", "native", pkg.MANIFEST.sides, None, "x")
    plan = BridgePlan.from_package(pkg, "vehicle")
    assert guard_for(plan, plan.options()) is None


def test_build_refuses_a_protected_rmw_desert_topic(tmp_path, capsys):
    (tmp_path / "i" / "n_msgs" / "msg").mkdir(parents=True)
    (tmp_path / "i" / "n_msgs" / "msg" / "Note.msg").write_text("string text\n")
    (tmp_path / "i" / "uwgen.yaml").write_text(
        "network: demo\nsecurity: {mode: sign, key_file: k}\n"
        "sides: {surface: {port: 4000, sender_id: 1}, vehicle: {port: 4001, sender_id: 2}}\n"
        "topics:\n  - {name: /cmd, id: 4, type: geometry_msgs/msg/Twist, publisher: surface,"
        " profile: rmw_desert}\n")
    rc = main(["build", str(tmp_path / "i"), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2
    assert "uwgen.yaml:2:" in err and "rmw_desert" in err and "cannot be signed or encrypted" in err


def test_final_summary_names_the_security_counts():
    from uwgen.bridge.main import _summary
    line = _summary({"security": {"protected": 4, "verified": 7, "dropped": 25}})
    assert line == "security: protected 4 verified 7 dropped 25"
    assert "security" not in _summary({"security": None})


def test_the_seals_max_age_of_a_service_or_action_is_its_own_deadline(tmp_path):
    """A call held past its timeout is refused by the seal as well, not after the 120 s
    default (docs/seams.md section 8)."""
    assert main(["keygen", str(tmp_path / "net.key")]) == 0
    pkg = package(tmp_path)
    pkg.MANIFEST.security.modes.update({20: "sign", 30: "sign"})
    pkg.SERVICES = {20: SimpleNamespace(id=20, name="/enable", server="vehicle", timeout=12.0,
                                        policy=SimpleNamespace(ttl=None), fingerprint=b"")}
    pkg.ACTIONS = {30: SimpleNamespace(id=30, name="/dive", server="vehicle", accept_timeout=9.0,
                                       policy=SimpleNamespace(ttl=None), fingerprint=b"")}
    plan = BridgePlan.from_package(pkg, "vehicle")
    guard = guard_for(plan, plan.options())
    assert guard.config.max_ages[20] == 12.0 and guard.config.max_ages[30] == 9.0
