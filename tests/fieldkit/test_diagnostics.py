"""/diagnostics levels from the bridge's status: the Assessor alone, on a manual clock."""
from __future__ import annotations

from uwgen.bridge.diagnostics import ERROR, HOLD, OK, WARN, Assessor
from uwgen.runtime.clock import ManualClock


def status(connected=True, expired=0, queued=0, security=0, delivered=0, lost=0, reconnects=0):
    return {
        "link": {"connected": connected, "connection": {"reconnects": reconnects}},
        "security": {"dropped": security},
        "topics": {"/cmd": {"id": 4, "direction": "out", "decode_errors": 0,
                            "link": {"expired": expired, "queued": queued,
                                     "on_link": {"delivered": delivered, "lost_on_link": lost}}}},
    }


def levels(assessor, st):
    return {v.name.split()[-1]: v.level for v in assessor.assess(st)}


def test_all_well_is_ok_for_the_bridge_and_each_entry():
    a = Assessor("net", "surface", {4: 8}, clock=ManualClock())
    got = a.assess(status())
    assert [(v.name, v.level, v.message) for v in got] == [
        ("uwgen net/surface", OK, "OK"), ("uwgen net/surface topic /cmd", OK, "OK")]


def test_link_down_is_error_for_the_bridge_and_warn_for_its_entries():
    a = Assessor("net", "surface", clock=ManualClock())
    assert levels(a, status(connected=False)) == {"net/surface": ERROR, "/cmd": WARN}
    bridge = a.assess(status(connected=False))[0]
    assert "link down" in bridge.message and bridge.values["connected"] == "False"


def test_drops_warn_while_they_happen_and_for_hold_seconds_after():
    clock = ManualClock()
    a = Assessor("net", "surface", clock=clock)
    a.assess(status())
    clock.advance(1)
    v = a.assess(status(expired=3))[1]
    assert v.level == WARN and "3 expired" in v.message
    clock.advance(HOLD - 1)
    assert a.assess(status(expired=3))[1].level == WARN
    clock.advance(2)
    assert a.assess(status(expired=3))[1].level == OK


def test_security_drops_and_reconnects_warn_on_the_bridge():
    clock = ManualClock()
    a = Assessor("net", "surface", clock=clock)
    a.assess(status())
    v = a.assess(status(security=2, reconnects=1))[0]
    assert v.level == WARN and "2 frames dropped as not authentic" in v.message
    assert "1 reconnects" in v.message


def test_a_full_queue_warns():
    a = Assessor("net", "surface", {4: 4}, clock=ManualClock())
    v = a.assess(status(queued=4))[1]
    assert v.level == WARN and "queue full (4 of 4)" in v.message


def test_delivery_ratio_under_thresholds_warns_then_errs():
    a = Assessor("net", "surface", clock=ManualClock())
    a.assess(status())
    v = a.assess(status(delivered=3, lost=5))[1]
    assert v.level == WARN and v.values["delivery_ratio"] == "0.38"
    v = a.assess(status(delivered=3, lost=15))[1]
    assert v.level == ERROR
    v = a.assess(status(delivered=13, lost=15))[1]
    assert v.level == OK and v.values["delivery_ratio"] == "1.00"


def test_extra_checks_judge_the_bridge_status():
    def turn_health(st):
        return [(WARN, "MAC turn missed")] if st.get("mac", {}).get("missed") else []
    a = Assessor("net", "surface", clock=ManualClock(), checks=[turn_health])
    assert a.assess({**status(), "mac": {"missed": 1}})[0].message == "MAC turn missed"


def test_mac_turns_missed_warn_on_the_bridge():
    clock = ManualClock()
    a = Assessor("net", "surface", clock=clock)
    st = status()
    st["link"]["mac"] = {"mode": "turns", "missed": 0, "dropped_turns": 0}
    assert a.assess(st)[0].level == OK
    st["link"]["mac"] = {"mode": "turns", "missed": 2, "dropped_turns": 0}
    v = a.assess(st)[0]
    assert v.level == WARN and "2 MAC turns missed" in v.message and v.values["mac"] == "turns"


def test_mac_answers_later_than_their_bound_warn_that_the_range_is_wrong():
    a = Assessor("net", "surface", clock=ManualClock())
    st = status()
    st["link"]["mac"] = {"mode": "turns", "missed": 0, "late_answers": 0}
    assert a.assess(st)[0].level == OK
    st["link"]["mac"] = {"mode": "turns", "missed": 0, "late_answers": 1}
    v = a.assess(st)[0]
    assert v.level == WARN and "range or bitrate" in v.message
