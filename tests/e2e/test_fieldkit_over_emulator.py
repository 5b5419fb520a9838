"""The field kit over the emulator: /diagnostics through a link outage, and both bridges'
recordings of what crossed, read by the standard MCAP tools and by `uwgen log`."""
from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from std_msgs.msg import String

from uwgen.bridge import diagnostics
from uwgen.fieldkit.reader import read_recordings
from uwgen.fieldkit.summary import summarise

from bridge.fakes import wait_for

from .conftest import network

OK, WARN, ERROR = (int.from_bytes(x, "little") for x in
                   (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR))


def test_diagnostics_go_error_when_the_link_is_cut_and_back_to_ok(e2e_package, monkeypatch):
    monkeypatch.setattr(diagnostics, "HOLD", 3.0)       # a reconnect warns 3 s, not 10
    with network(e2e_package, bridges=()) as net:
        seen: list[tuple[float, dict[str, int]]] = []
        net.surface.node("monitor").create_subscription(
            DiagnosticArray, "/diagnostics",
            lambda m: seen.append((time.monotonic(), {s.name: s.level[0] if isinstance(s.level, bytes)
                                                      else int(s.level) for s in m.status})), 10)
        for side in ("surface", "vehicle"):
            net.start_bridge(side, diagnostics_period=0.2)
        bridge, entry = "uwgen e2e/surface", "uwgen e2e/surface topic /cmd_vel"

        def latest(name):
            return seen[-1][1].get(name) if seen else None
        wait_for(lambda: latest(bridge) == OK, timeout=15.0, what="the bridge OK")
        assert latest(entry) == OK
        net.emu.restart(delay=3.0, wait=False)             # DESERT dies, back in 3 s
        wait_for(lambda: latest(bridge) == ERROR, timeout=10.0, what="ERROR while the link is down")
        assert latest(entry) == WARN
        wait_for(lambda: latest(bridge) == WARN and net.connected(), timeout=15.0,
                 what="reconnected: WARN (a reconnect) while it is recent")
        wait_for(lambda: latest(bridge) == OK, timeout=diagnostics.HOLD + 10.0, what="OK again")
        assert latest(entry) == OK


def test_both_bridges_record_what_crossed(e2e_package, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    files = {s: tmp_path / f"{s}.mcap" for s in ("surface", "vehicle")}
    with network(e2e_package, bridges=()) as net:
        for side in ("surface", "vehicle"):
            net.start_bridge(side, record=files[side])
        logs: list = []
        net.surface.node("op").create_subscription(String, "/log", logs.append, 10)
        cmds: list = []
        net.vehicle.node("sim").create_subscription(Twist, "/cmd_vel", cmds.append, 10)
        log_pub = net.vehicle.node("sim_pub").create_publisher(String, "/log", 10)
        cmd_pub = net.surface.node("op_pub").create_publisher(Twist, "/cmd_vel", 10)
        wait_for(lambda: net.connected() and log_pub.get_subscription_count()
                 and cmd_pub.get_subscription_count(), what="bridges up")
        both_up = time.time()     # a packet written before the far side connected had no reader
        texts = [f"log line {k}" for k in range(5)]
        for text in texts:
            log_pub.publish(String(data=text))
        twist = Twist()
        twist.linear.x = 0.25
        cmd_pub.publish(twist)
        wait_for(lambda: len(logs) == 5 and cmds, timeout=15.0, what="logs and the command")
        time.sleep(0.5)                                   # the last acknowledgements cross
        closing = time.time()                             # what leaves later has no reader
        for side in ("surface", "vehicle"):
            net.bridges[side].close()                     # the recordings are finished

    with open(files["vehicle"], "rb") as f:                # what the vehicle's bridge took
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        taken = [d.data for _s, _c, _m, d in reader.iter_decoded_messages(topics=["/log"])]
    assert taken == texts
    with open(files["surface"], "rb") as f:                # and the surface's published
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert [d.data for _s, _c, _m, d in reader.iter_decoded_messages(topics=["/log"])] == texts

    summary = summarise(read_recordings(list(files.values())))
    rows = {r.name: r for r in summary.topics}
    log = rows["/log"]
    assert (log.direction, log.published, log.taken, log.on_link, log.lost, log.delivered) == \
        ("vehicle → surface", 5, 5, 5, 0, 5)
    assert len(log.latencies) == 5 and all(0 < x < 5 for x in log.latencies)
    assert rows["/cmd_vel"].delivered == 1
    for side in summary.sides.values():                   # no packet lost at PER 0
        before = [arrived for t, _b, arrived in side.sent if both_up <= t < closing - 0.2]
        assert before and all(before), side
        assert side.received["delivered"] > 0
