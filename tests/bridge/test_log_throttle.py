"""Error lines a remote peer can cause are bounded: once, then counted, then a periodic summary."""
from __future__ import annotations

import logging
import threading

from geometry_msgs.msg import Twist
from test_msgs.srv import BasicTypes

from uwgen.bridge.throttle import LogThrottle
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.reassembly import Reassembler

from .fakes import FakeServiceCodec, FakeTopicCodec, LinkPair, fake_package, wait_for
from .harness import ros_sides, start_bridge

SLOW = FakeServiceCodec(21, "/slow", BasicTypes, "vehicle", timeout=0.4)
CMD = FakeTopicCodec(4, "/cmd", Twist, "surface")


def test_first_occurrence_is_logged_then_counted_then_summarised():
    clock, lines = ManualClock(), []
    t = LogThrottle(lines.append, clock, every=60.0)
    for seq in range(500):
        t.report("noserver21", f"/slow: request seq {seq} not served")
    assert lines == ["/slow: request seq 0 not served (further ones are counted, summarised every 60 s)"]
    t.tick()
    assert len(lines) == 1                      # not time yet
    clock.advance(60.0)
    t.tick()
    assert lines[1].startswith("499 more since the last summary (500 in all) like: /slow: request seq 0")
    clock.advance(60.0)
    t.tick()
    assert len(lines) == 2                      # nothing new: no summary line
    assert t.totals == {"noserver21": 500}


def test_kinds_are_throttled_separately():
    lines = []
    t = LogThrottle(lines.append, ManualClock())
    t.report("a", "A happened")
    t.report("b", "B happened")
    t.report("a", "A again")
    assert [line.split(" (")[0] for line in lines] == ["A happened", "B happened"]


def test_a_flood_of_requests_for_a_service_without_server_logs_one_line():
    package = fake_package([CMD], [SLOW])
    links = LinkPair()
    with ros_sides("vehicle") as (vehicle,):
        bridge = start_bridge(vehicle, package, links.factory)
        lines: list[str] = []
        bridge.wiring.throttle._emit = lines.append
        for seq in range(1000):               # a peer (or a forger) sending requests nobody serves
            links.links["vehicle"].inject(SLOW.encode_request(seq % 65536, BasicTypes.Request()))
        wait_for(lambda: bridge.service_counters[SLOW.id].no_server == 1000, timeout=20.0,
                 what="every request counted")
    # One line while it went on; the bridge's close adds the summary of the rest.
    assert len(lines) == 2 and "not served" in lines[0]
    assert lines[1].startswith("999 more since the last summary (1000 in all) like:")
    assert bridge.wiring.throttle.totals == {f"noserver{SLOW.id}": 1000}


def test_a_flood_of_forged_fragments_logs_a_logarithmic_number_of_lines(caplog):
    reasm = Reassembler(250, ManualClock())
    with caplog.at_level(logging.WARNING, logger="uwgen.link.fragment"):
        for i in range(10_000):
            reasm.feed(bytes([0x00, 0x18, 0xFA, i % 256, 0x05, 0x02]))    # index 5 of count 2, no chunk
    assert reasm.stats["malformed"] == 10_000
    assert len(caplog.records) <= 5                # the 1st, 10th, 100th, 1000th, 10000th


def test_expected_losses_are_warnings_with_counts_and_other_problems_errors():
    clock, errors, warnings = ManualClock(), [], []
    t = LogThrottle(errors.append, clock, every=60.0, warn=warnings.append)
    for seq in range(3):
        t.report("timeout21", f"/slow: call seq {seq} got no response within 1 s: failed", expected=True)
    t.report("noserver21", "/slow: request seq 9 not served")
    clock.advance(60.0)
    t.tick()
    assert [w.split(" (")[0] for w in warnings] == ["/slow: call seq 0 got no response within 1 s: failed",
                                                    "2 more since the last summary"]
    assert len(errors) == 1 and "not served" in errors[0]


def test_a_bridged_call_that_times_out_is_a_warning_not_an_error():
    package = fake_package([CMD], [SLOW])
    links = LinkPair()
    with ros_sides("surface") as (surface,):
        bridge = start_bridge(surface, package, links.factory)
        errors, warnings = [], []
        bridge.wiring.throttle._emit, bridge.wiring.throttle._warn = errors.append, warnings.append
        client = surface.node("caller").create_client(BasicTypes, "/slow")
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(BasicTypes.Request())     # the far side never answers
        wait_for(lambda: bridge.service_counters[SLOW.id].timeouts == 1, timeout=10.0,
                 what="the call timed out")
    assert errors == [] and len(warnings) == 1 and "got no response within 0.4 s" in warnings[0]
    assert not future.done() or future.result() is None


def test_warnings_and_errors_through_one_rclpy_logger_never_raise():
    # rclpy keys a logger's calls by their call site and refuses one whose severity changes
    # (ValueError): the throttle's warnings and errors must each have a call site of their own
    from rclpy.impl.rcutils_logger import RcutilsLogger
    log = RcutilsLogger("uwgen_throttle_test")
    clock = ManualClock()
    t = LogThrottle(log.error, clock, every=10.0, warn=log.warning)
    t.report("lost_answer", "an answer was lost", expected=True)
    t.report("bad_bytes", "bytes that do not decode")
    t.report("lost_answer", "again")
    t.report("bad_bytes", "again")
    clock.advance(10.0)
    t.tick()                                    # both summaries, through the same logger
    assert t.totals == {"lost_answer": 2, "bad_bytes": 2}


class RaisingExecutor:
    """An executor whose callbacks raise `fails` times, then stop the bridge."""

    def __init__(self, fails: int, stop):
        self.fails, self.stop, self.spins = fails, stop, 0

    def spin_once(self, timeout_sec=None):
        self.spins += 1
        if self.spins <= self.fails:
            raise RuntimeError(f"callback bug {self.spins}")
        self.stop.set()


def test_a_callback_that_raises_is_counted_and_the_bridge_spins_on():
    from uwgen.bridge.main import spin
    stop, failed = threading.Event(), []
    executor = RaisingExecutor(3, stop)
    spin(executor, stop, ok=lambda: True, failed=lambda exc: failed.append(str(exc)))
    assert failed == ["callback bug 1", "callback bug 2", "callback bug 3"] and executor.spins == 4


def test_a_spin_that_fails_because_ros_shut_down_is_no_callback_bug():
    from uwgen.bridge.main import spin
    stop, failed, up = threading.Event(), [], [True]

    class ShuttingDown:
        def spin_once(self, timeout_sec=None):
            up[0] = False                     # the context went down during the spin
            raise RuntimeError("context is not valid")
    spin(ShuttingDown(), stop, ok=lambda: up[0], failed=failed.append)
    assert failed == []


def test_a_failed_callback_is_logged_once_with_its_traceback_and_counted_in_status():
    from uwgen.bridge.main import callback_failed
    links = LinkPair()
    with ros_sides("vehicle") as (vehicle,):
        bridge = start_bridge(vehicle, fake_package([CMD], [SLOW]), links.factory)
        lines: list[str] = []
        bridge.wiring.throttle._emit = lines.append
        errors: list[str] = []
        bridge.wiring.log = type("Log", (), {"error": lambda self, text: errors.append(text)})()
        for _ in range(3):
            try:
                raise KeyError("boom")
            except KeyError as exc:
                callback_failed(bridge, exc)
        assert bridge.status()["bridge"]["callback_errors"] == 3
    assert len(errors) == 1 and "Traceback" in errors[0] and "KeyError: 'boom'" in errors[0]
    assert bridge.wiring.throttle.totals == {"callback:KeyError": 3}
