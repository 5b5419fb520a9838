"""Security composes with the compact encodings: profile packed and field encodings travel
protected, and the guard hands back exactly the payload the codec made."""
from __future__ import annotations

import pytest

from uwgen.codegen import generate
from uwgen.security.guard import GuardConfig, LinkGuard

from .helpers import KEY

MANIFEST = """\
network: packsec
security: {mode: encrypt, key_file: net.key}
sides:
  surface: {port: 4000, sender_id: 1}
  vehicle: {port: 4001, sender_id: 2}
topics:
  - name: /cmd_vel
    id: 4
    type: geometry_msgs/msg/Twist
    publisher: surface
    rate: 2
    queue: fifo        # every message leaves (a latest topic is counted once a packet)
    profile: packed
    fields:
      linear.x: {min: -2, max: 2, precision: 2}
      angular.z: {min: -3.2, max: 3.2, resolution: 0.05}
  - name: /battery
    id: 6
    type: sensor_msgs/msg/BatteryState
    publisher: vehicle
    security: sign
    fields:
      voltage: {min: 0, max: 30, precision: 1}
      cell_voltage[]: {min: 0, max: 5, precision: 2}
"""


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    root = tmp_path_factory.mktemp("packsec")
    (root / "uwgen.yaml").write_text(MANIFEST)
    return generate(root / "out", "uwgen_packsec", manifest=root / "uwgen.yaml")


def test_packed_and_encoded_fields_travel_protected(pkg, tmp_path):
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import BatteryState
    assert pkg.MANIFEST.security.modes == {4: "encrypt", 6: "sign"}
    fps = {i: pkg.TOPICS[i].fingerprint for i in (4, 6)}
    tx = LinkGuard.for_key(KEY, GuardConfig("packsec", 1, {2: "vehicle"}, {4: "encrypt", 6: "sign"}, fps),
                           tmp_path / "tx")
    rx = LinkGuard.for_key(KEY, GuardConfig("packsec", 2, {1: "surface"}, {4: "encrypt", 6: "sign"}, fps),
                           tmp_path / "rx")
    twist = Twist()
    twist.linear.x, twist.angular.z = 1.25, -0.5
    battery = BatteryState(voltage=15.8, cell_voltage=[3.95, 3.96])
    for ident, msg in ((4, twist), (6, battery)):
        payload = pkg.TOPICS[ident].encode(msg)
        frame = tx.protect(ident, payload)
        assert len(frame) - len(payload) in (10, 23)
        back = rx.unprotect(frame)
        assert back == payload
        decoded = pkg.TOPICS[ident].decode(back)
        assert type(decoded) is type(msg)
    assert pkg.TOPICS[4].decode(rx.unprotect(tx.protect(4, pkg.TOPICS[4].encode(twist)))).linear.x == 1.25
    assert rx.stats()["dropped"] == 0


def test_analyze_counts_the_security_overhead_in_every_protected_frame(tmp_path):
    from uwgen.analyze import analyze
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.manifest.loader import load_manifest
    lib = InterfaceLibrary([], installed=True)
    (tmp_path / "on").mkdir()
    (tmp_path / "off").mkdir()
    (tmp_path / "on" / "uwgen.yaml").write_text(MANIFEST)
    (tmp_path / "off" / "uwgen.yaml").write_text(MANIFEST.replace("mode: encrypt", "mode: off")
                                                 .replace("security: sign", "security: off"))
    on = analyze(load_manifest(tmp_path / "on" / "uwgen.yaml", lib), lib.get)
    off = analyze(load_manifest(tmp_path / "off" / "uwgen.yaml", lib), lib.get)
    # wire format 2: one tag per packet (8 bytes; 21 on a sync packet, 23 when it also asks)
    for a, b in zip(on.entries, off.entries):
        fa, fb = a.configured.frame, b.configured.frame
        assert fa.typical - fb.typical == 8
        assert fa.max is fb.max is None or fa.max - fb.max == 23      # None: unbounded (a string)
        assert a.configured.payload == b.configured.payload       # the codec's bytes are the same
    surface_on, surface_off = (next(x for x in r.budgets if x.side == "surface") for r in (on, off))
    assert surface_on.typical - surface_off.typical == 2 * 8        # 2 frames a second


@pytest.mark.parametrize("tag", [4, 6])
def test_analyze_counts_the_manifests_tag_length(tmp_path, tag):
    from uwgen.analyze import analyze
    from uwgen.analyze_report import format_analysis
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.manifest.loader import load_manifest
    lib = InterfaceLibrary([], installed=True)
    results = {}
    for n in (8, tag):
        (tmp_path / str(n)).mkdir()
        (tmp_path / str(n) / "uwgen.yaml").write_text(MANIFEST.replace(
            "key_file: net.key}", f"key_file: net.key, tag_bytes: {n}}}"))
        results[n] = analyze(load_manifest(tmp_path / str(n) / "uwgen.yaml", lib), lib.get)
    for a, b in zip(results[8].entries, results[tag].entries):
        fa, fb = a.configured.frame, b.configured.frame
        assert fa.typical - fb.typical == 8 - tag                  # the tag, every packet
        assert fa.max is fb.max is None or fb.max - (tag + 15) == fa.max - 23
    budgets = [next(x for x in r.budgets if x.side == "surface") for r in (results[8], results[tag])]
    assert budgets[0].typical - budgets[1].typical == pytest.approx(2 * (8 - tag))   # 2 frames/s
    assert results[tag].tag_bytes == tag
    text = format_analysis(results[tag], {"surface": 64, "vehicle": 64})
    assert f"one {tag}-byte tag per packet" in text and f"2^-{8 * tag} per packet" in text
