"""Log volume has a steady-state bound whatever the input rate: at most one drop line per
entry per minute (the first at once), each error kind once and then one summary a minute,
and at shutdown one line with whatever was not yet said. The numbers in the lines add up
to everything counted: bounded, never silent."""
from __future__ import annotations

import re
from types import SimpleNamespace

from uwgen.bridge.status import REPORT_EVERY, StatusReporter
from uwgen.bridge.throttle import LogThrottle
from uwgen.runtime.clock import ManualClock

ENTRIES = ["/cmd_vel", "/pose", "/battery"]


class Lines:
    """A logger that keeps its lines."""

    def __init__(self):
        self.lines: list[str] = []

    def warning(self, text):
        self.lines.append(text)

    info = error = warning


def reporter(clock):
    node = SimpleNamespace(create_publisher=lambda *a, **k: SimpleNamespace(publish=lambda m: None))
    log = Lines()
    wiring = SimpleNamespace(node=node, clock=clock, log=log, said=set(),
                             options=SimpleNamespace(stats_file=None))
    return StatusReporter(wiring, "n", "surface"), log


def status(k: int) -> dict:
    """The status after `k` reports of steady overload: every entry drops 7 per report."""
    return {"topics": {name: {"link": {"expired": 7 * k, "queue_full": 3 * k}, "encode_errors": 0}
                       for name in ENTRIES},
            "services": {}, "actions": {}, "bridge": {"unknown_id": k, "inbox_overflow": 0}}


def test_drop_lines_are_at_most_one_per_entry_a_minute_under_any_rate_and_add_up():
    clock = ManualClock()
    rep, log = reporter(clock)
    minutes, every = 10, 0.05                     # a report every 50 ms: 40x the default rate
    k = 0
    while clock.now() < minutes * 60:
        k += 1
        clock.advance(every)
        rep.publish(status(k))
    steady = len(log.lines)
    rep.final_report(status(k))
    # Bound: per entry (3 topics + the bridge's own) the first line and one a minute.
    assert steady <= (len(ENTRIES) + 1) * (1 + minutes * 60 / REPORT_EVERY)
    assert steady >= (len(ENTRIES) + 1) * minutes * 60 / REPORT_EVERY     # but they do come
    assert len(log.lines) == steady + 1 and log.lines[-1].startswith("at shutdown, dropped since the last report:")
    # Nothing lost: the numbers logged for each entry add up to everything it dropped.
    for name, per_report in ((n, 7) for n in ENTRIES):
        said = sum(int(n) for line in log.lines for n in re.findall(
            rf"{re.escape(name)}:? (?:dropped since last report: )?(\d+) expired", line))
        assert said == per_report * k, (name, said)
    said = sum(int(n) for line in log.lines for n in re.findall(r"(\d+) unknown id", line))
    assert said == k


def test_a_steady_overload_of_a_day_logs_a_bounded_number_of_bytes():
    clock = ManualClock()
    rep, log = reporter(clock)
    k = 0
    while clock.now() < 24 * 3600:
        k += 1
        clock.advance(2.0)                        # the default status period
        rep.publish(status(k))
    size = sum(len(line) + 40 for line in log.lines)     # + the logger's time and name prefix
    per_day_bound = (len(ENTRIES) + 1) * (1 + 24 * 3600 / REPORT_EVERY) * (max(map(len, log.lines)) + 40)
    assert size <= per_day_bound and size < 2_000_000, size   # was 45 MB a day at 0.5 KB/s


def test_error_kinds_are_summarised_once_a_minute_and_flushed_at_shutdown():
    clock, lines = ManualClock(), []
    t = LogThrottle(lines.append, clock, every=60.0)
    for step in range(10 * 60 * 100):             # 100 per second for 10 minutes, two kinds
        t.report("noserver21", "/slow: request not served")
        t.report("timeout22", "/other: call timed out")
        clock.advance(0.01)
        t.tick()
    t.report("noserver21", "/slow: request not served")
    before = len(lines)
    assert before <= 2 * (1 + 10)
    t.flush()                                     # at shutdown
    assert len(lines) == before + 2
    counted = {"noserver21": 1, "timeout22": 1}   # the first occurrences, logged in full
    for line in lines:
        m = re.match(r"(\d+) more since the last summary \((\d+) in all\) like: /(\w+)", line)
        if m:
            counted["noserver21" if m.group(3) == "slow" else "timeout22"] += int(m.group(1))
    assert counted == t.totals == {"noserver21": 60001, "timeout22": 60000}
